"""Wall-clock pacing of simulated time (:class:`Pacer`) and throttled reports
(:class:`Throttle`)."""

from __future__ import annotations

import math
import threading
import time


class Pacer:
    """Wall-clock pacing of simulated time: ``wait(t)`` returns when ``t`` (s,
    simulated) is due at ``real_time_factor`` simulated seconds per wall
    second, counting from the first call; 0 never waits."""

    def __init__(self, real_time_factor: float, stop: threading.Event | None = None):
        self.factor = real_time_factor
        self._stop = stop or threading.Event()
        self._origin = None

    def wait(self, t: float) -> None:
        if self.factor <= 0:
            return
        now = time.monotonic()
        if self._origin is None:
            self._origin = now - t / self.factor
        delay = self._origin + t / self.factor - now
        if delay > 0:
            self._stop.wait(delay)


class Throttle:
    """At most one report per ``period`` s (wall clock) of each kind: the first
    at once, the others counted and told with the next one, so a stream of
    bad messages gives a line a second instead of a line a message.

    ``throttle(kind)`` returns None to stay quiet, else how many reports of
    that kind were held back since the last one.
    """

    def __init__(self, period: float = 1.0, clock=time.monotonic):
        self.period = period
        self._clock = clock
        self._last: dict = {}
        self._held: dict = {}

    def __call__(self, kind: str) -> int | None:
        now = self._clock()
        if now - self._last.get(kind, -math.inf) < self.period:
            self._held[kind] = self._held.get(kind, 0) + 1
            return None
        self._last[kind] = now
        return self._held.pop(kind, 0)

"""Progress of long work on stderr: a tqdm bar in a terminal, plain lines otherwise.

Logs and CI stay readable (no carriage returns when stderr is not a
terminal); a person at a terminal sees one live line instead of a scroll.
"""

from __future__ import annotations

import sys
import time

from tqdm import tqdm

#: Without a terminal, a plain line at most this often (s), and at the end.
LINE_EVERY = 5.0


def time_left(elapsed: float, done: int, total: int | None) -> str:
    """", N s left at this pace" for ``done`` of ``total`` steps in ``elapsed``
    s, or "" once done or without a total: what a log reader of a long job (an
    8 x 8 search: most of an hour) wants to know; an upper bound where the work
    may stop short of its total, as a search short of its budget."""
    if total is None or not 0 < done < total:
        return ""
    return f", {elapsed * (total - done) / done:.0f} s left at this pace"


class Progress:
    """Count ``total`` steps of ``desc``; use as a context manager.

    Parameters
    ----------
    total : int or None
        Steps expected (None: a counter without an end).
    desc : str
    units : str
        What the steps are, plural ("evaluations", "copies").
    file : text stream, optional
        Default ``sys.stderr``; a bar only if it is a terminal.
    enabled : bool
        False shows nothing (``--quiet``).
    """

    def __init__(self, total, desc: str, units: str, *, file=None, enabled: bool = True):
        self.file = sys.stderr if file is None else file
        self.enabled = enabled
        self.total, self.desc, self.units = total, desc, units
        self.done = 0
        self._printed = 0  # steps done at the last plain line
        self._postfix = ""
        self._start = self._shown = time.monotonic()
        terminal = enabled and getattr(self.file, "isatty", lambda: False)()
        self._bar = tqdm(total=total, desc=desc, unit=f" {units}", file=self.file,
                         dynamic_ncols=True, leave=True) if terminal else None

    @property
    def live(self) -> bool:
        """A bar is drawn (stderr is a terminal): callers may skip their own lines."""
        return self._bar is not None

    def update(self, n: int = 1, **postfix) -> None:
        """``n`` more steps done; ``postfix`` (name=value) is shown beside the count."""
        self.done += n
        if postfix:
            self._postfix = ", ".join(f"{k} {v}" for k, v in postfix.items())
        if self._bar is not None:
            if postfix:
                self._bar.set_postfix_str(self._postfix, refresh=False)
            self._bar.update(n)
        elif self.enabled and time.monotonic() - self._shown >= LINE_EVERY:
            self._line()

    def _line(self) -> None:
        self._shown = time.monotonic()
        self._printed = self.done
        of = f"/{self.total}" if self.total is not None else ""
        extra = f", {self._postfix}" if self._postfix else ""
        elapsed = self._shown - self._start
        print(f"{self.desc}: {self.done}{of} {self.units}{extra}, {elapsed:.1f} s"
              f"{time_left(elapsed, self.done, self.total)}", file=self.file, flush=True)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
        elif self.enabled and self.done != self._printed:
            self._line()

    def __enter__(self):
        return self

    def __exit__(self, exc_type, *exc):
        # an error ends the work with its own one line: no count line after it
        # (a drawn bar is closed, and stays on the terminal above the error)
        if exc_type is None or self._bar is not None:
            self.close()

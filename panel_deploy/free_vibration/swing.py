"""One recorded swing: its samples, its extrema, and the checks that it is worth
analysing (enough peaks above the noise, no stop reached), read from a recording.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import TrajectoryError
from .rig import Rig, rig_of


#: Fewest extrema (peaks and troughs) a test needs: four peak-to-peak
#: amplitudes give the decrement's regression two degrees of freedom.
MIN_PEAKS = 5
#: Peaks are used while their amplitude about the equilibrium is at least this
#: many noise standard deviations: below, noise biases the ratios.
PEAK_SNR = 20.0
#: A record whose range is below this many noise standard deviations is motionless.
MOTION_SNR = 50.0


@dataclass(frozen=True)
class Swing:
    """One recorded free vibration: ``t`` (s, from the first sample) and ``theta`` (rad)."""

    source: str
    t: np.ndarray
    theta: np.ndarray


def noise_level(theta) -> float:
    """The white noise's standard deviation in ``theta``, rad, from fourth
    differences (the noise's grow sqrt(70) fold; a swing sampled 30 times per
    period adds (2 pi / 30)^4 = 0.2 % of its amplitude), median-based so that
    a few outliers do not count."""
    d4 = np.diff(np.asarray(theta, dtype=float), 4)
    return float(np.median(np.abs(d4 - np.median(d4))) / 0.6745 / np.sqrt(70.0))


@dataclass(frozen=True)
class Peaks:
    """Alternating extrema of a swing: times (s) and values (rad), in order;
    the record's noise (standard deviation, rad) and the equilibrium the
    extrema decay towards (rad)."""

    t: np.ndarray
    theta: np.ndarray
    noise: float
    equilibrium: float


def _lobes(theta, centre, band):
    """Index ranges of the excursions beyond centre +- band, alternating in sign."""
    side = np.where(theta > centre + band, 1, np.where(theta < centre - band, -1, 0))
    lobes, start, sign = [], None, 0
    for j, s in enumerate(side):
        if s == 0 or s == sign:
            continue
        if sign != 0:
            lobes.append((start, j, sign))
        start, sign = j, s
    if sign != 0:
        lobes.append((start, len(theta), sign))
    return lobes


def _vertex(t, theta, j, half):
    """The extremum near sample j: the vertex of a parabola fitted to the
    2 half + 1 samples around it (averages the noise; a cosine is a parabola
    to 0.1 % within a sixteenth of its period)."""
    lo, hi = max(j - half, 0), min(j + half + 1, len(t))
    if hi - lo < 3:
        return t[j], theta[j]
    tc = t[lo:hi] - t[j]
    a, b, c = np.polyfit(tc, theta[lo:hi], 2)
    if a == 0 or not tc[0] <= -b / (2 * a) <= tc[-1]:
        return t[j], theta[j]
    x = -b / (2 * a)
    return t[j] + x, c - b * b / (4 * a)


def find_peaks(swing: Swing) -> Peaks:
    """The swing's alternating peaks and troughs above :data:`PEAK_SNR` x noise.

    The first and the last excursion are left out: the first holds the
    release (a hand lets go over some ms, perhaps after holding the panel
    still) or starts mid-swing, the last may be cut by the record's end.
    """
    t, theta = swing.t, swing.theta
    noise = max(noise_level(theta), 1e-12 * max(1.0, float(np.ptp(theta))))
    centre = float(np.median(theta))
    band = 5.0 * noise
    values = times = np.empty(0)
    for _ in range(2):  # the median, then the peaks' own equilibrium, as the centre
        inner = _lobes(theta, centre, band)[1:-1]
        if not inner:
            break
        # a parabola over +- a sixteenth of the period (an inner lobe lasts half of one)
        half_period = float(np.median([t[b] - t[a] for a, b, _ in inner]))
        half = max(1, int(round(half_period / 8.0 / float(np.median(np.diff(t))))))
        extrema = [_vertex(t, theta, a + int(np.argmax(s * theta[a:b])), half)
                   for a, b, s in inner]
        times = np.array([e[0] for e in extrema])
        values = np.array([e[1] for e in extrema])
        centre = _equilibrium(values, centre)
    keep = np.abs(values - centre) >= PEAK_SNR * noise
    # the peaks from the first to the last strong one (a weak one inside is kept:
    # dropping it would break the alternation)
    strong = np.flatnonzero(keep)
    part = slice(strong[0], strong[-1] + 1) if len(strong) else slice(0, 0)
    return Peaks(times[part], values[part], noise, centre)


def _equilibrium(values, fallback: float) -> float:
    """The centre of alternating extrema decaying geometrically: with ratio q
    per half cycle, e = (q y_j + y_{j+1}) / (1 + q) for every pair."""
    if len(values) < 3:
        return fallback
    d = np.abs(np.diff(values))
    q = float(np.median(d[1:] / d[:-1]))
    if not 0 < q < 1:
        return fallback
    return float(np.median((q * values[:-1] + values[1:]) / (1 + q)))


def check_swing(swing: Swing, rig: Rig) -> Peaks:
    """The swing's peaks, once it is known to be a free vibration this module can read.

    Raises
    ------
    TrajectoryError
        One line naming the file: too few samples, motionless, reaching a
        joint stop (0 or pi rad), fewer than :data:`MIN_PEAKS` peaks above
        the noise, or peaks that do not decay.
    """
    src, theta = swing.source, swing.theta
    if len(theta) < 20:
        raise TrajectoryError(f"{src}: {len(theta)} joint states of {rig.hinge}; a free "
                              f"vibration needs a record of many samples per swing")
    noise = noise_level(theta)
    span = float(np.ptp(theta))
    if span <= MOTION_SNR * noise or span < 1e-9:
        raise TrajectoryError(f"{src}: motionless: {rig.hinge} spans {span:.3g} rad, less than "
                              f"{MOTION_SNR:g} x its noise ({noise:.2g} rad)")
    low, high = float(theta.min()), float(theta.max())
    if low < -3 * noise or high > np.pi + 3 * noise:
        raise TrajectoryError(f"{src}: {rig.hinge} reaches a joint stop ({low:.3g} .. {high:.3g} "
                              f"rad against 0 .. pi): a swing against a stop is no free vibration "
                              f"of the spring")
    peaks = find_peaks(swing)
    if len(peaks.t) < MIN_PEAKS:
        raise TrajectoryError(f"{src}: too few peaks: {len(peaks.t)} peaks and troughs above "
                              f"{PEAK_SNR:g} x the noise ({peaks.noise:.2g} rad), at least "
                              f"{MIN_PEAKS} needed (two swings after the release)")
    delta = decrement(peaks)[0]
    if not delta > 0:
        raise TrajectoryError(f"{src}: the swing does not decay (log decrement {delta:.3g}): "
                              f"not the free vibration of a damped spring")
    return peaks


def regression(x, y):
    """Slope, intercept, the slope's standard error and the residual scatter of y on x."""
    A = np.column_stack([x, np.ones_like(x)])
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    r = y - A @ coef
    dof = len(x) - 2
    s2 = float(r @ r) / dof if dof > 0 else float("nan")
    cov = s2 * np.linalg.inv(A.T @ A)
    return float(coef[0]), float(coef[1]), float(np.sqrt(cov[0, 0])), float(np.sqrt(s2))


def decrement(peaks: Peaks) -> tuple:
    """delta, its standard error and the scatter of the ln peak-to-peak
    amplitudes about their regression line on the half-cycle count."""
    d = np.abs(np.diff(peaks.theta))
    slope, _, se_slope, scatter = regression(np.arange(len(d), dtype=float), np.log(d))
    return -2.0 * slope, 2.0 * se_slope, scatter


def read_swing(path, rig_scene: str | None = None, namespace: str | None = None) -> tuple:
    """``(swing, rig, peaks)`` of one recording, checked (:func:`check_swing`).

    The rig is the recording's own scene, else ``rig_scene`` (a file or a
    shipped name) when given; the angles are those of its one hinge.

    Raises
    ------
    TrajectoryError
        No such file, not a recording, no scene, not one panel on one hinge,
        or a record :func:`check_swing` refuses.
    SceneError
        ``rig_scene`` is not a valid scene.
    """
    from ..record.analysis import read_deployment

    d = read_deployment(path, rig_scene, namespace, scene_flag="--rig")
    rig = rig_of(d.model, str(path))
    swing = Swing(str(path), d.track.t, d.track.theta[:, 0])
    return swing, rig, check_swing(swing, rig)

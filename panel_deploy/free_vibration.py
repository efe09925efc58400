"""Free-vibration tests: hinge damping (and stiffness, and air drag) from recordings
of one panel swinging on one spring-loaded hinge, as the paper measured damping.

The rig is a scene of two bodies and one hinge (ground and panel; a 2 x 2
array merges into that). About the hinge axis it is one degree of freedom,

    I theta'' = -n k (theta - theta_e) - n c theta' + G(theta) - G(theta_e) - C_d D |theta'| theta'

with n springs of stiffness k (N m/rad) and damping c (N m s/rad) each, the
panel's inertia I (kg m^2), its gravity torque G (N m) and its air drag
torque per unit drag coefficient D (N m s^2), all three from the rig's model
(:func:`rig_of`). The equilibrium theta_e is measured, not computed: it takes
up the encoder's zero and the weight's preload, so k is identified by the
frequency alone. The joint stops are not in it: a swing that reaches one is
refused (:func:`check_swing`).

Each test is analysed two ways: the logarithmic decrement of its peaks
(:func:`log_decrement`) and a least-squares fit of the model's free response
(:func:`fit_swing`); :func:`pool` combines the tests by inverse-variance
weighting and says whether they agree. Failures to fit are results
(``success=False``), never exceptions; exceptions are for bad input.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .errors import TrajectoryError
from .model import AirParameters

#: Fewest extrema (peaks and troughs) a test needs: four peak-to-peak
#: amplitudes give the decrement's regression two degrees of freedom.
MIN_PEAKS = 5
#: Peaks are used while their amplitude about the equilibrium is at least this
#: many noise standard deviations: below, noise biases the ratios.
PEAK_SNR = 20.0
#: A record whose range is below this many noise standard deviations is motionless.
MOTION_SNR = 50.0
#: The drag coefficient counts as identified when its standard error is below
#: this (a coefficient of order 1 known to +-0.5 at 95 %) and its estimate is
#: not almost collinear with the damping's.
DRAG_SE_LIMIT = 0.25
COLLINEAR = 0.98
#: The fit searches c and k within this (natural log) of its start, a factor 1000.
SPAN = np.log(1000.0)
#: Confidence level of every interval.
LEVEL = 0.95


@dataclass(frozen=True)
class Rig:
    """One panel on one hinge, about the hinge axis (SI units).

    ``gravity`` holds (g0, g1, g2) of the gravity torque G(theta) = g0 + g1
    sin(theta) + g2 cos(theta), N m: one rigid body turning about a fixed axis
    has exactly this form. ``drag`` is D, the air torque -C_d D |omega| omega
    per unit drag coefficient, N m s^2 (0 without air). ``k`` and ``c`` are
    the rig scene's own, of one spring.
    """

    hinge: str
    springs: int
    inertia: float
    gravity: tuple
    drag: float
    drag_coefficient: float
    k: float
    c: float

    def gravity_torque(self, theta):
        g0, g1, g2 = self.gravity
        return g0 + g1 * np.sin(theta) + g2 * np.cos(theta)

    def gravity_gradient(self, theta):
        """dG/dtheta, N m/rad (negative: gravity stiffens the swing)."""
        _, g1, g2 = self.gravity
        return g1 * np.cos(theta) - g2 * np.sin(theta)


def rig_of(model, source: str = "") -> Rig:
    """The :class:`Rig` of a model of one panel on one hinge.

    I, G and D come from the dynamics kernels' own mass matrix and
    generalised forces, so the rig obeys the package's model exactly.

    Raises
    ------
    TrajectoryError
        The model is not two bodies joined by one hinge (``source`` names the recording).
    """
    from .dynamics.kernels import mass_and_bias
    from .dynamics.panel_contact import near_pairs
    from .dynamics.pack import pack

    if len(model.hinges) != 1 or model.n_coords != 1:
        raise TrajectoryError(f"{source}: not one panel on one hinge: its scene has "
                              f"{model.n_bodies} bodies and {len(model.hinges)} hinges")
    h = model.hinges[0]
    P = pack(model)
    free = P._replace(k=np.zeros_like(P.k), c=np.zeros_like(P.c))

    def force(P, theta, omega):
        return float(mass_and_bias(P, np.array([theta]), np.array([omega]), near_pairs(P))[1][0])

    angles = (0.0, 0.5 * np.pi, np.pi)
    g = np.linalg.solve([[1.0, np.sin(a), np.cos(a)] for a in angles],
                        [force(free, a, 0.0) for a in angles])
    drag = 0.0
    if model.air.density > 0:
        # with a unit drag coefficient, D is the torque at omega = 1 rad/s
        unit = pack(replace(model, air=AirParameters(model.air.density, 1.0)))
        unit = unit._replace(k=free.k, c=free.c)
        drag = force(unit, 1.0, 0.0) - force(unit, 1.0, 1.0)
    inertia = float(mass_and_bias(P, np.array([1.0]), np.array([0.0]), near_pairs(P))[0][0, 0])
    return Rig(h.name, int(h.springs), inertia, tuple(float(x) for x in g), float(drag),
               float(model.air.drag_coefficient if model.air.density > 0 else 0.0),
               float(h.k), float(h.c))


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
    delta = _decrement(peaks)[0]
    if not delta > 0:
        raise TrajectoryError(f"{src}: the swing does not decay (log decrement {delta:.3g}): "
                              f"not the free vibration of a damped spring")
    return peaks


def _quantile(dof: float) -> float:
    """Student's t quantile of the two-sided :data:`LEVEL` interval."""
    from scipy.stats import t as student

    return float(student.ppf(0.5 + LEVEL / 2, dof))


@dataclass(frozen=True)
class Estimate:
    """A quantity with its standard error and 95 % interval [low, high], SI
    units. ``log``: a positive quantity estimated in log space, ``se`` that
    of its logarithm (a relative error); else ``se`` is absolute."""

    value: float
    se: float
    low: float
    high: float
    log: bool = True

    @classmethod
    def from_log(cls, log_value: float, se: float, dof: float) -> Estimate:
        """From ln value and its standard error, with ``dof`` degrees of freedom."""
        half = _quantile(dof) * se
        return cls(float(np.exp(log_value)), float(se), float(np.exp(log_value - half)),
                   float(np.exp(log_value + half)))

    @classmethod
    def linear(cls, value: float, se: float, dof: float, floor: float = -np.inf) -> Estimate:
        """From the value and its standard error; the interval cut at ``floor``."""
        half = _quantile(dof) * se
        return cls(float(value), float(se), max(floor, float(value) - half),
                   float(value) + half, log=False)

    def figures(self) -> dict:
        """value, its standard error (``relative_se`` in log space, else
        ``se``), low and high, as plain floats to six significant digits."""
        se = "relative_se" if self.log else "se"
        return {"value": float(f"{self.value:.6g}"), se: float(f"{self.se:.3g}"),
                "low": float(f"{self.low:.6g}"), "high": float(f"{self.high:.6g}")}

    def text(self) -> str:
        """``value +- standard error [low, high]`` for the report."""
        se = f"{self.se:.2%}" if self.log else f"{self.se:.2g}"
        return f"{self.value:.5g} +- {se} [{self.low:.5g}, {self.high:.5g}]"


@dataclass(frozen=True)
class Analysis:
    """One test analysed one way (``method``: "log decrement" or "fit").

    ``c`` and ``k`` are of one spring (N m s/rad, N m/rad), ``ratio`` is
    c/k (s); ``drag`` the drag coefficient when identified, else None with
    the reason in ``notes``. ``equilibrium`` rad; ``rms`` the fit's residual
    RMS (rad) or the scatter of the decrement's ln peak-to-peak amplitudes.
    """

    source: str
    method: str
    success: bool
    message: str = ""
    c: Estimate | None = None
    k: Estimate | None = None
    ratio: Estimate | None = None
    zeta: float = float("nan")
    drag: Estimate | None = None
    equilibrium: float = float("nan")
    rms: float = float("nan")
    peaks: int = 0
    notes: tuple = field(default_factory=tuple)


def _regression(x, y):
    """Slope, intercept, the slope's standard error and the residual scatter of y on x."""
    A = np.column_stack([x, np.ones_like(x)])
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    r = y - A @ coef
    dof = len(x) - 2
    s2 = float(r @ r) / dof if dof > 0 else float("nan")
    cov = s2 * np.linalg.inv(A.T @ A)
    return float(coef[0]), float(coef[1]), float(np.sqrt(cov[0, 0])), float(np.sqrt(s2))


def _decrement(peaks: Peaks) -> tuple:
    """delta, its standard error and the scatter of the ln peak-to-peak
    amplitudes about their regression line on the half-cycle count."""
    d = np.abs(np.diff(peaks.theta))
    slope, _, se_slope, scatter = _regression(np.arange(len(d), dtype=float), np.log(d))
    return -2.0 * slope, 2.0 * se_slope, scatter


def log_decrement(swing: Swing, rig: Rig, peaks: Peaks) -> Analysis:
    """c and k of one spring from the peaks' decay and spacing.

    The peak-to-peak amplitudes d_j = |y_j - y_{j+1}| of extrema half a
    period apart fall by e^(-delta/2) per half cycle whatever the
    equilibrium, so delta comes from a regression of ln d_j on j and the
    damped period T_d from one of the peak times on j. Then zeta =
    delta / sqrt(4 pi^2 + delta^2), n c = 2 zeta omega_n I = 2 I delta / T_d
    and n k = I omega_n^2 + dG/dtheta at the equilibrium. With air the decrement
    counts the drag as damping.
    """
    delta, se_delta, scatter = _decrement(peaks)
    half_period, _, se_half, _ = _regression(np.arange(len(peaks.t), dtype=float), peaks.t)
    period, se_period = 2.0 * half_period, 2.0 * se_half
    n, inertia = rig.springs, rig.inertia
    zeta = delta / np.sqrt(4 * np.pi ** 2 + delta ** 2)
    k_eff = inertia * (4 * np.pi ** 2 + delta ** 2) / period ** 2
    k_hinge = k_eff + float(rig.gravity_gradient(peaks.equilibrium))
    if not k_hinge > 0:  # a hinge without a spring, swung by the weight alone
        return Analysis(swing.source, "log decrement", False,
                        f"the weight alone explains the swing's frequency (n k = {k_hinge:.3g} "
                        f"N m/rad): no spring stiffness to measure", peaks=len(peaks.t))
    c_hinge = 2.0 * inertia * delta / period
    # first-order propagation of delta's and T_d's errors (two separate regressions)
    g_c = np.array([1.0 / delta, -1.0 / period])
    g_k = k_eff / k_hinge * np.array([2 * delta / (4 * np.pi ** 2 + delta ** 2), -2.0 / period])
    cov = np.diag([se_delta ** 2, se_period ** 2])
    dof = len(peaks.t) - 3  # the regression of len(peaks.t) - 1 amplitudes

    def estimate(value, gradient):
        return Estimate.from_log(np.log(value), float(np.sqrt(gradient @ cov @ gradient)), dof)

    return Analysis(swing.source, "log decrement", True,
                    c=estimate(c_hinge / n, g_c), k=estimate(k_hinge / n, g_k),
                    ratio=estimate(c_hinge / k_hinge, g_c - g_k), zeta=float(zeta),
                    equilibrium=peaks.equilibrium, rms=scatter, peaks=len(peaks.t),
                    notes=("counts the air drag as damping",) if rig.drag > 0 else ())


class _Response:
    """The model's free response and its sensitivities to the parameters
    (forward sensitivity equations, integrated with the motion: one solve
    gives residuals and Jacobian). Parameters: ln c, ln k (one spring),
    theta_e, theta_0, omega_0 at the first sample, then C_d when fitted."""

    def __init__(self, rig: Rig, t, drag_coefficient: float | None):
        self.rig, self.t = rig, t
        self.fixed_drag = drag_coefficient  # None: C_d is the sixth parameter
        self._x = None

    def parameters(self, x):
        cd = x[5] if self.fixed_drag is None else self.fixed_drag
        return np.exp(x[0]), np.exp(x[1]), x[2], x[3], x[4], cd

    def solve(self, x):
        if self._x is not None and np.array_equal(x, self._x):
            return self._out
        from scipy.integrate import odeint

        rig, p = self.rig, len(x)
        c, k, te, t0, w0, cd = self.parameters(x)
        n, inertia, D = rig.springs, rig.inertia, rig.drag
        ge, dge = rig.gravity_torque(te), rig.gravity_gradient(te)

        def rhs(y, _):
            th, w = y[0], y[1]
            S = y[2:].reshape(2, p)
            acc = (-n * k * (th - te) - n * c * w + rig.gravity_torque(th) - ge
                   - cd * D * abs(w) * w) / inertia
            d_th = (-n * k + rig.gravity_gradient(th)) / inertia
            d_w = (-n * c - 2.0 * cd * D * abs(w)) / inertia
            direct = np.zeros(p)
            direct[0] = -n * c * w / inertia
            direct[1] = -n * k * (th - te) / inertia
            direct[2] = (n * k - dge) / inertia
            if self.fixed_drag is None:
                direct[5] = -D * abs(w) * w / inertia
            return np.concatenate([[w, acc], S[1], d_th * S[0] + d_w * S[1] + direct])

        y0 = np.zeros(2 + 2 * p)
        y0[:2] = t0, w0
        y0[2 + 3] = 1.0           # d theta(0) / d theta_0
        y0[2 + p + 4] = 1.0       # d omega(0) / d omega_0
        y = odeint(rhs, y0, self.t, rtol=1e-10, atol=1e-12, mxstep=100000)
        self._x, self._out = np.array(x), (y[:, 0], y[:, 2:2 + p])
        return self._out


def fit_swing(swing: Swing, rig: Rig, peaks: Peaks, start: Analysis,
              fit_drag: bool | None = None) -> Analysis:
    """c, k (and C_d) of one spring by least squares of the model's free
    response on the recorded angles from the first peak on, every sample
    weighted alike (an encoder's noise does not depend on the angle).

    ``start`` (the log decrement) gives the starting point. ``fit_drag``
    None fits C_d when the rig has air and keeps it only if identified (see
    :data:`DRAG_SE_LIMIT`); otherwise the rig's own C_d is used and the
    notes say why. c and k are fitted in log space: they stay positive and
    their intervals are relative, as their errors are. C_d is fitted as it
    is, within the scene's [0, 5]: no drag at all is a value it may take.
    """
    from scipy.optimize import least_squares

    if fit_drag is None:
        fit_drag = rig.drag > 0
    first = np.searchsorted(swing.t, peaks.t[0])
    t = swing.t[first:] - swing.t[first]
    theta = swing.theta[first:]
    model = _Response(rig, t, None if fit_drag else rig.drag_coefficient)
    c0 = start.c.value if start.success else max(rig.c, 1e-9)
    k0 = start.k.value if start.success else max(rig.k, 1e-9)
    x0 = [np.log(c0), np.log(k0), peaks.equilibrium, theta[0], 0.0]
    # c and k within SPAN of the start: a trust-region step far out (k x 1e4) makes
    # the response so stiff that one integration takes minutes
    lower = [x0[0] - SPAN, x0[1] - SPAN] + [-np.inf] * 3
    upper = [x0[0] + SPAN, x0[1] + SPAN] + [np.inf] * 3
    if fit_drag:
        x0.append(max(rig.drag_coefficient, 0.5))
        lower.append(0.0)
        upper.append(5.0)  # the scene's own limit of air.drag_coefficient

    def residual(x):
        return model.solve(x)[0] - theta

    def jacobian(x):
        return model.solve(x)[1]

    try:
        sol = least_squares(residual, x0, jac=jacobian, bounds=(lower, upper), x_scale="jac",
                            method="trf", xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=200)
    except (ValueError, np.linalg.LinAlgError) as e:  # an integration that blew up
        return Analysis(swing.source, "fit", False, f"the fit failed ({e})", peaks=len(peaks.t))
    if not sol.success:
        return Analysis(swing.source, "fit", False, f"the fit did not converge ({sol.message})",
                        peaks=len(peaks.t))
    if np.any(sol.active_mask[:2]):
        return Analysis(swing.source, "fit", False, "the fit ran to the edge of its search (c or k "
                        "a factor 1000 from its start): the model does not describe this record",
                        peaks=len(peaks.t))
    dof = len(t) - len(sol.x)
    rms = float(np.sqrt(np.mean(sol.fun ** 2)))
    s2 = float(sol.fun @ sol.fun) / dof
    try:
        cov = s2 * np.linalg.inv(sol.jac.T @ sol.jac)
    except np.linalg.LinAlgError:
        return Analysis(swing.source, "fit", False, "the fit's parameters are not "
                        "identifiable (singular Jacobian)", peaks=len(peaks.t))
    notes = []
    if fit_drag:
        se_cd = float(np.sqrt(cov[5, 5]))
        corr = float(cov[0, 5] / np.sqrt(cov[0, 0] * cov[5, 5]))
        if se_cd > DRAG_SE_LIMIT or abs(corr) > COLLINEAR:
            refit = fit_swing(swing, rig, peaks, start, fit_drag=False)
            why = (f"drag not identifiable from this record (C_d = {round(sol.x[5], 3):g} +- "
                   f"{se_cd:.2g}, correlation with c {corr:+.3f}): c and k given the scene's "
                   f"C_d = {rig.drag_coefficient:g}")
            return replace(refit, notes=(why, *refit.notes))
    cov_log = cov[:2, :2]
    g_ratio = np.array([1.0, -1.0])
    c = Estimate.from_log(sol.x[0], float(np.sqrt(cov_log[0, 0])), dof)
    k = Estimate.from_log(sol.x[1], float(np.sqrt(cov_log[1, 1])), dof)
    ratio = Estimate.from_log(sol.x[0] - sol.x[1], float(np.sqrt(g_ratio @ cov_log @ g_ratio)), dof)
    drag = None
    if fit_drag:
        drag = Estimate.linear(sol.x[5], np.sqrt(cov[5, 5]), dof, floor=0.0)
    if rms > 3.0 * peaks.noise:
        notes.append(f"the model misses the record: residual {rms:.2g} rad RMS against "
                     f"{peaks.noise:.2g} rad of noise")
    k_eff = rig.springs * k.value - float(rig.gravity_gradient(sol.x[2]))
    zeta = rig.springs * c.value / (2.0 * np.sqrt(k_eff * rig.inertia))
    return Analysis(swing.source, "fit", True, c=c, k=k, ratio=ratio, zeta=float(zeta),
                    drag=drag, equilibrium=float(sol.x[2]), rms=rms, peaks=len(peaks.t),
                    notes=tuple(notes))


@dataclass(frozen=True)
class Pooled:
    """Estimates of several tests combined by inverse-variance weights.

    ``chi2`` on ``dof`` degrees of freedom tests whether they agree (``p``
    its probability under agreement). When they do not (p < 0.05), the
    interval is widened by the Birge ratio sqrt(chi2 / dof): the tests
    scatter more than their own errors say.
    """

    estimate: Estimate
    chi2: float
    dof: int
    p: float
    widened: bool

    @property
    def agree(self) -> bool:
        return self.dof == 0 or self.p >= 1 - LEVEL


def pool(estimates) -> Pooled:
    """Inverse-variance weighted mean of estimates (of logarithms for those in log space)."""
    from scipy.stats import chi2 as chi_square

    log = estimates[0].log
    x = np.array([np.log(e.value) if log else e.value for e in estimates])
    w = 1.0 / np.array([max(e.se, 1e-12) for e in estimates]) ** 2
    mean = float(w @ x / w.sum())
    se_mean = float(1.0 / np.sqrt(w.sum()))
    dof = len(estimates) - 1
    chi2 = float(w @ (x - mean) ** 2)
    p = float(chi_square.sf(chi2, dof)) if dof else 1.0
    widened = dof > 0 and p < 1 - LEVEL
    if widened:
        se_mean *= np.sqrt(chi2 / dof)
    estimate = (Estimate.from_log(mean, se_mean, np.inf) if log
                else Estimate.linear(mean, se_mean, np.inf, floor=0.0))
    return Pooled(estimate, chi2, dof, p, widened)


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
    from .record.analysis import read_deployment

    d = read_deployment(path, rig_scene, namespace, scene_flag="--rig")
    rig = rig_of(d.model, str(path))
    swing = Swing(str(path), d.track.t, d.track.theta[:, 0])
    return swing, rig, check_swing(swing, rig)


@dataclass(frozen=True)
class Calibration:
    """Every test analysed both ways and the tests pooled.

    ``tests`` holds ``(log_decrement, fit)`` per recording; ``fit`` and
    ``log_decrement`` map "c", "k", "ratio" (and the fit "drag", when some
    test identified it) to their :class:`Pooled` over the tests that
    succeeded; empty when none did.
    """

    tests: tuple
    fit: dict
    log_decrement: dict

    @property
    def success(self) -> bool:
        return "ratio" in self.fit


def _pooled(analyses, names) -> dict:
    out = {}
    for name in names:
        found = [getattr(a, name) for a in analyses if a.success and getattr(a, name) is not None]
        if found:
            out[name] = pool(found)
    return out


def calibrate(readings) -> Calibration:
    """Analyse ``readings`` (``(swing, rig, peaks)`` from :func:`read_swing`)
    by log decrement and by fit, and pool them."""
    tests = []
    for swing, rig, peaks in readings:
        decrement = log_decrement(swing, rig, peaks)
        tests.append((decrement, fit_swing(swing, rig, peaks, decrement)))
    return Calibration(tuple(tests), _pooled([f for _, f in tests], ("c", "k", "ratio", "drag")),
                       _pooled([d for d, _ in tests], ("c", "k", "ratio")))


#: Units of the figures (c and k of one spring).
UNITS = {"c": "N m s/rad", "k": "N m/rad", "ratio": "s", "drag": ""}
LABELS = {"c": "c", "k": "k", "ratio": "c/k", "drag": "C_d"}


def calibration_record(cal: Calibration, hinge: str | None = None) -> dict:
    """The ``calibration`` section of a calibrated scene (plain values, YAML
    and JSON alike): the pooled fit with its intervals and agreement, the
    pooled log decrement, and every test."""
    def pooled(found):
        return {name: {**p.estimate.figures(), "unit": UNITS[name], "chi2": round(p.chi2, 3),
                       "dof": p.dof, "p": round(p.p, 4), "widened": p.widened}
                for name, p in found.items()}

    tests = []
    for decrement, fit in cal.tests:
        test = {"recording": fit.source, "peaks": fit.peaks}
        for a in (fit, decrement):
            key = "fit" if a is fit else "log_decrement"
            test[key] = ({name: getattr(a, name).figures() for name in ("c", "k", "ratio", "drag")
                          if getattr(a, name) is not None} if a.success else {"failed": a.message})
            if a.success:
                test[key].update({"zeta": float(f"{a.zeta:.6g}"),
                                  "rms_rad" if a is fit else "scatter_ln": float(f"{a.rms:.3g}")})
            if a.notes:
                test[key]["notes"] = list(a.notes)
        tests.append(test)
    return {"method": "free vibration: fit of the one-hinge model's free response (log "
                      "decrement beside it); c and k of one spring",
            "confidence": LEVEL,
            **({"hinge": hinge} if hinge else {}),
            "fit": pooled(cal.fit), "log_decrement": pooled(cal.log_decrement), "tests": tests}


def calibrated_scene(data: dict, cal: Calibration, hinge: str | None = None) -> dict:
    """Scene ``data`` with the pooled fit's damping: ``hinges.damping_ratio``
    = c/k, or with ``hinge`` that hinge's ``hinges.damping_overrides`` entry =
    c (N m s/rad, one spring); and :func:`calibration_record` as the
    ``calibration`` section's ``free_vibration`` entry, beside what other
    calibrations of the scene wrote there."""
    out = dict(data)
    hinges = dict(out.get("hinges") or {})
    if hinge is None:
        hinges["damping_ratio"] = cal.fit["ratio"].estimate.figures()["value"]
    else:
        hinges["damping_overrides"] = {**(hinges.get("damping_overrides") or {}),
                                       hinge: cal.fit["c"].estimate.figures()["value"]}
    out["hinges"] = hinges
    out["calibration"] = {**(out.get("calibration") or {}),
                          "free_vibration": calibration_record(cal, hinge)}
    return out


def _line(label, e: Estimate, unit="") -> str:
    return f"  {label:<6} {e.text()} {unit}".rstrip()


def report_text(cal: Calibration) -> str:
    """The human report: every test both ways, then the pooled figures."""
    lines = []
    for decrement, fit in cal.tests:
        lines.append(f"{fit.source}: {fit.peaks} peaks")
        for a in (decrement, fit):
            if not a.success:
                lines.append(f"  {a.method}: failed: {a.message}")
                continue
            spread = (f"residual {a.rms:.2g} rad RMS" if a is fit
                      else f"ln amplitude scatter {a.rms:.2g}")
            lines.append(f"  {a.method}: zeta {a.zeta:.4g}, equilibrium {a.equilibrium:.4g} rad, "
                         f"{spread}")
            lines += ["  " + _line(LABELS[n], getattr(a, n), UNITS[n])
                      for n in ("c", "k", "ratio", "drag") if getattr(a, n) is not None]
            lines += [f"    note: {note}" for note in a.notes]
    for title, found in (("fit", cal.fit), ("log decrement", cal.log_decrement)):
        if not found:
            lines.append(f"pooled {title}: no test succeeded")
            continue
        lines.append(f"pooled {title} ({found['c'].dof + 1} tests, {LEVEL:.0%} intervals):")
        for name, p in found.items():
            verdict = ("" if p.dof == 0 else
                       f"  chi2 {p.chi2:.3g} on {p.dof}, p {p.p:.3g}"
                       + (": the tests disagree, interval widened" if p.widened else ""))
            lines.append(_line(LABELS[name], p.estimate, UNITS[name]) + verdict)
    return "\n".join(lines)


def released(rig: Rig, t, c: float, k: float, equilibrium: float, amplitude: float):
    """theta(t), rad, of a rig without weight or air released at rest from
    ``equilibrium + amplitude`` at t = 0: the closed form of the underdamped
    oscillator, the reference the tests and the benchmark measure against.

    Raises
    ------
    ModelError
        The rig has weight or air (no closed form), or c and k (one spring,
        N m s/rad and N m/rad) do not make it underdamped.
    """
    from .errors import ModelError

    if rig.drag > 0 or np.any(np.abs(rig.gravity) > 0):
        raise ModelError("released: the closed form is for a rig without weight and air")
    n = rig.springs
    wn = np.sqrt(n * k / rig.inertia)
    zeta = n * c / (2.0 * np.sqrt(n * k * rig.inertia))
    if not 0 <= zeta < 1:
        raise ModelError(f"released: zeta = {zeta:.3g}, not an underdamped oscillator")
    wd = wn * np.sqrt(1.0 - zeta ** 2)
    t = np.asarray(t, dtype=float)
    return equilibrium + amplitude * np.exp(-zeta * wn * t) * (
        np.cos(wd * t) + zeta * wn / wd * np.sin(wd * t))


def record_swing(path, scene, t, theta, t0: float = 0.0, carry_scene: bool = True) -> None:
    """Write a swing of ``scene``'s one hinge as a recording: ``theta`` (rad)
    at ``t`` (s, stamped from ``t0``) on ``/joint_states``, and the scene on
    ``panel_deploy/model`` unless ``carry_scene`` is False (a real rig's
    ``ros2 bag record /joint_states``, read with ``--rig``)."""
    from . import contract
    from .build import build_model
    from .record import messages
    from .record.writer import DeploymentWriter
    from .scene_text import scene_yaml

    name = rig_of(build_model(scene), str(path)).hinge
    empty = np.zeros(0)
    with DeploymentWriter(path) as rec:
        if carry_scene:
            rec.write(contract.MODEL, messages.string(scene_yaml(scene)))
        for time, value in zip(t, theta):
            rec.write(contract.JOINT_STATES,
                      messages.joint_state([name], t0 + time, [value], empty, empty))

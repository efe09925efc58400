"""Estimates of one swing's damping and stiffness (and drag): the logarithmic
decrement of its peaks and a least-squares fit of the rig's free response; and
estimates of several tests pooled by inverse-variance weighting.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .rig import Rig
from .swing import Peaks, Swing, decrement, regression


#: The drag coefficient counts as identified when its standard error is below
#: this (a coefficient of order 1 known to +-0.5 at 95 %) and its estimate is
#: not almost collinear with the damping's.
DRAG_SE_LIMIT = 0.25


COLLINEAR = 0.98
#: The fit searches c and k within this (natural log) of its start, a factor 1000.
SPAN = np.log(1000.0)
#: Confidence level of every interval.
LEVEL = 0.95


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
    delta, se_delta, scatter = decrement(peaks)
    half_period, _, se_half, _ = regression(np.arange(len(peaks.t), dtype=float), peaks.t)
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

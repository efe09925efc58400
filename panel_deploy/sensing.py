"""Joint states from the hinges a real array measures: the unmeasured tree
hinges solved from the loop closure.

A stream must give the tree coordinates (``model.joints``) to place every
body; a real array may measure another spanning set instead, e.g. the cut
hinge and all but one hinge of its loop. The closure the model holds (for
each cut hinge j, its two ends carried by bodies a and b coincide, and its
angle is the measured one when the stream gives it) then determines the
rest. :class:`LoopSolver` finds them by Gauss-Newton on those equations,
starting from the previous sample's solution (the stowed angles at first),
so a deployment stays on its branch of the loop's solutions.

Angles in rad, rates in rad/s, lengths in m.
"""

from __future__ import annotations

import numpy as np

from .dynamics.kernels import loop_residual
from .dynamics.pack import pack
from .model import hinge_order
from .errors import TrajectoryError
from .model import Model

#: Chord-method steps at most per sample; from the previous sample's solution
#: a few reach STEP_TOL.
MAX_STEPS = 20
#: Converged once no unknown angle moves more than this, rad.
STEP_TOL = 1e-11
#: Forward-difference step of the Jacobian, rad.
FD_STEP = 1e-7
#: Largest loop gap (m) a solution may leave: measured angles that cannot
#: close the loop within it (a wrong joint name, a bad encoder) are refused.
GAP_LIMIT = 0.01
#: Singular values below this fraction of the largest entry of the closure
#: Jacobian count as zero: forward differences are good to ~1e-7 of it.
RANK_TOL = 1e-4


class LoopSolver:
    """The tree angles a stream lacks, from the angles it carries.

    Parameters
    ----------
    model : Model
    measured : iterable of str
        Hinge names the stream carries (tree and cut hinges).

    Attributes
    ----------
    missing : list of int
        Tree coordinates to solve for (indices into theta).
    last_gap : float
        Largest loop gap left by the last solution, m.

    Raises
    ------
    TrajectoryError
        Naming a missing hinge that the measured ones do not determine
        (not on a loop, or too few of its loop measured).
    """

    def __init__(self, model: Model, measured):
        self.model = model
        self._packed = pack(model)
        order = hinge_order(model)
        names = [model.hinges[h].name for h in order]
        measured = set(measured)
        n = model.n_coords
        self.tree_names = names[:n]
        self.missing = [i for i in range(n) if names[i] not in measured]
        self.known = [i for i in range(n) if names[i] in measured]
        self.cut_names = [names[n + j] for j in range(len(model.cut_hinges))
                          if names[n + j] in measured]
        self._cut_rows = [j for j in range(len(model.cut_hinges)) if names[n + j] in measured]
        # Angle residuals in m, comparable with the gaps: times the largest body.
        self._scale = max(float(np.linalg.norm(b.size)) for b in model.bodies)
        self._guess = np.asarray(model.theta_stowed, dtype=float)[self.missing]
        self._cut_target = np.zeros(len(self._cut_rows))
        self.last_gap = 0.0
        self._pinv = None  # pseudo-inverse of the last solution's Jacobian: the next chord
        self._check_determined()

    def _check_determined(self) -> None:
        if not self.missing:
            return
        theta = self._closed_state()
        J, _ = self._jacobian(theta, self._cut_residual_at(theta))
        rank = np.linalg.matrix_rank(J, tol=RANK_TOL * np.abs(J).max())
        if rank == len(self.missing):
            return
        for i, x in enumerate(self.missing):
            if np.abs(J[:, i]).max() <= 1e-9:
                raise TrajectoryError(f"name: missing joint {self.tree_names[x]!r}: it is on no "
                                      f"loop, so the stream must carry it")
        names = ", ".join(repr(self.tree_names[x]) for x in self.missing)
        raise TrajectoryError(f"name: missing joints {names}: the hinges carried do not determine "
                              f"them (carry more hinges of their loop)")

    def _closed_state(self) -> np.ndarray:
        """A generic state that closes every loop, half deployed: the stowed
        and flat ones are singular for some loops (folded hinges line up),
        and away from closure the gap equations have a rank they lose on it."""
        theta = 0.5 * np.asarray(self.model.theta_stowed, dtype=float) + 0.1
        P, n = self._packed, self.model.n_coords
        for _ in range(MAX_STEPS):
            r = loop_residual(P, theta)[:, :6].ravel()
            J = np.empty((r.size, n))
            for i in range(n):
                th = theta.copy()
                th[i] += FD_STEP
                J[:, i] = (loop_residual(P, th)[:, :6].ravel() - r) / FD_STEP
            step = np.linalg.lstsq(J, -r, rcond=None)[0]
            theta += step
            if not np.abs(step).max() > STEP_TOL:
                break
        return theta

    def _cut_residual_at(self, theta):
        """Cut angles at ``theta``: a target that makes the measured-angle rows vanish there."""
        return loop_residual(self._packed, theta)[self._cut_rows, 6]

    def _residual(self, theta, cut_target):
        r = loop_residual(self._packed, theta)
        gaps = r[:, :6].ravel()
        angles = (r[self._cut_rows, 6] - cut_target) * self._scale
        return np.concatenate([gaps, angles])

    def _jacobian(self, theta, cut_target) -> tuple:
        """``(J, r)``: d r / d theta of the missing angles, and r, at ``theta``."""
        r0 = self._residual(theta, cut_target)
        J = np.empty((r0.size, len(self.missing)))
        for i, x in enumerate(self.missing):
            th = theta.copy()
            th[x] += FD_STEP
            J[:, i] = (self._residual(th, cut_target) - r0) / FD_STEP
        return J, r0

    def solve(self, theta_known, cut_theta, omega_known=None, cut_omega=None) -> tuple:
        """Full tree angles (and rates) from the measured ones.

        Parameters
        ----------
        theta_known : (len(known),) array_like
            Angles of the measured tree hinges, in coordinate order, rad.
        cut_theta : (len(cut_names),) array_like
            Angles of the measured cut hinges, rad.
        omega_known, cut_omega : array_like, optional
            Their rates, rad/s; without them the result has no rates.

        Returns
        -------
        (theta, omega) : (n_coords,) ndarray, and (n_coords,) ndarray or None

        Raises
        ------
        TrajectoryError
            When no angles close the loops to within ``GAP_LIMIT``.
        """
        n = self.model.n_coords
        theta = np.empty(n)
        theta[self.known] = theta_known
        cut_target = np.asarray(cut_theta, dtype=float)
        # The chord method from the previous solution: one Jacobian per sample is
        # enough for the small steps between samples. A jump (a new deployment,
        # a gap) gets Newton's method from the stowed angles instead.
        stowed = np.asarray(self.model.theta_stowed, dtype=float)[self.missing]
        # Least squares by the pseudo-inverse of each Jacobian, computed once: the
        # chord steps and the rates are then products (lstsq per step cost more
        # than the residuals).
        for x, chord in ((self._guess.copy(), self._pinv), (stowed, None)):
            theta[self.missing] = x
            pinv = chord
            for _ in range(MAX_STEPS):
                if chord is None or pinv is None:
                    pinv = _pinv(self._jacobian(theta, cut_target)[0])
                with np.errstate(all="ignore"):
                    step = -(pinv @ self._residual(theta, cut_target))
                x += step
                theta[self.missing] = x
                if not np.abs(step).max() > STEP_TOL:
                    break
            # At the solution: the rates need it exact, and it is the next sample's chord.
            J, r0 = self._jacobian(theta, cut_target)
            gap = float(np.abs(r0[:6 * len(self.model.cut_hinges)]).max(initial=0.0))
            if np.all(np.isfinite(x)) and gap <= GAP_LIMIT:
                break
        if not np.all(np.isfinite(x)) or gap > GAP_LIMIT:
            raise TrajectoryError(f"position: the carried angles leave the loop open by "
                                  f"{gap * 1e3:.3g} mm; cannot solve for "
                                  f"{self.tree_names[self.missing[0]]!r}")
        self._pinv, self._guess, self.last_gap = _pinv(J), x, gap
        if omega_known is None or (self.cut_names and cut_omega is None):
            return theta, None
        omega = np.zeros(n)
        omega[self.known] = omega_known
        # J_x omega_x = -(d r / d theta_known) omega_known: one directional difference.
        cut_rate = np.asarray(cut_omega if cut_omega is not None else (), dtype=float)
        moved = self._residual(theta + FD_STEP * omega, cut_target + FD_STEP * cut_rate)
        omega[self.missing] = -(self._pinv @ ((moved - r0) / FD_STEP))
        return theta, omega


def _pinv(J) -> np.ndarray:
    """Moore-Penrose pseudo-inverse of ``J`` (NaN where ``J`` is not finite: the
    solve then falls back or fails on its own terms)."""
    if not np.all(np.isfinite(J)):
        return np.full(J.shape[::-1], np.nan)
    return np.linalg.pinv(J)


class TreeCoordinates:
    """The tree angles and rates of any hinge set the loop closure completes:
    the columns the set carries, the rest solved (:class:`LoopSolver`, one
    per set of names, kept).

    Attributes
    ----------
    solved : list of str
        Tree hinges the last call solved from the loop closure.
    """

    def __init__(self, model: Model):
        self.model = model
        order = hinge_order(model)
        self.required = [model.hinges[h].name for h in order[:model.n_coords]]
        self._solvers: dict = {}
        self.solved: list = []

    def __call__(self, names, position, velocity=None) -> tuple:
        """``(theta, omega)`` of the tree coordinates (rad, rad/s; omega None
        without ``velocity``) from one sample's ``position`` (and ``velocity``)
        of hinges ``names``.

        Raises
        ------
        TrajectoryError
            Names that do not determine the tree's angles (naming one), or
            angles that cannot close the loop.
        """
        index = {name: i for i, name in enumerate(names)}
        position = np.asarray(position, dtype=float)
        velocity = None if velocity is None else np.asarray(velocity, dtype=float)
        if all(h in index for h in self.required):
            rows = [index[h] for h in self.required]
            self.solved = []
            return position[rows], None if velocity is None else velocity[rows]
        key = frozenset(index)
        if key not in self._solvers:
            self._solvers[key] = LoopSolver(self.model, key)
        solver = self._solvers[key]
        known = [index[solver.tree_names[i]] for i in solver.known]
        cuts = [index[name] for name in solver.cut_names]
        theta, omega = solver.solve(position[known], position[cuts],
                                    None if velocity is None else velocity[known],
                                    None if velocity is None else velocity[cuts])
        self.solved = [solver.tree_names[i] for i in solver.missing]
        return theta, omega

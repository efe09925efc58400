"""Scene files: the one place the schema of a run is defined.

A scene is a YAML mapping with the sections below; every key is optional
except ``array`` and has the default shown. Units are SI. :func:`load_scene`
validates everything and raises :class:`~panel_deploy.errors.SceneError`
naming the key path (``simulation.rtol: expected a number > 0, got -1``).
``panel-deploy schema`` prints this table.
"""

from __future__ import annotations

import copy
import math
import re
import sys
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import yaml

from .errors import SceneError, shown

#: ``simulation.method`` names: the integrators of
#: :data:`panel_deploy.dynamics.integrate.METHODS` (a test keeps the two equal).
INTEGRATORS = ("RK23", "RK45", "DOP853", "Radau", "BDF", "LSODA", "dopri5", "tsit5", "ros34pw2",
               "compiled")

# --- limits: sanity bounds stated in the schema, so absurd input fails at once ---
#: Panels along one side: the circuit search, packing check and model are
#: sized for arrays of this order (a 40 x 40 scene exhausted the recursion limit).
MAX_SIDE = 12
_WHY_SIDE = "the circuit search and the model are sized for arrays up to 12 x 12"
#: Sample instants of one run (memory: about 150 bytes per body per sample).
MAX_SAMPLES = 50_000
#: Accepted-step budget of a run (:func:`panel_deploy.dynamics.simulate`'s max_steps).
STEP_BUDGET = 2_000_000
_WHY_SCALE = "values this far from a real panel make the model's numbers degenerate"
_WHY_STIFF = "beyond this the integrator's step collapses long before the end time"
_WHY_G = "more than 1000 g makes the deployment a crash, not a run"
#: Least panel density, kg/m^3 (mass over the panel's box): the lightest solids,
#: aerogels, weigh 0.16 kg/m^3; a lighter panel is no panel, and its time
#: scales (a 1e-9 kg paper panel on its contact springs: 0.4 microseconds)
#: only exhaust the integrator's step budget.
MIN_DENSITY = 0.1
_WHY_DENSITY = "lighter than any solid (aerogels: 0.16 kg/m^3 and up)"
#: Normal speed, m/s, from which two panels in contact that meet collide
#: (``collision.impact_speed``, ``CollisionSettings.impact_speed``): below it
#: they press, as stacked panels do; the paper scene's impacts come at metres a
#: second, its presses at millimetres.
IMPACT_SPEED = 0.05

#: Broad-phase margin of the collision check, m (``CollisionSettings.margin``):
#: a pair farther apart than this is only bounded, never computed, so an
#: interference tolerance above it could not be told from a miss.
COLLISION_MARGIN = 0.02
#: Smallest ``collision.tolerance``, m. Panels touching by design (the stowed
#: stacks, slit neighbours when flat) are 0 apart, and a collision is
#: interference deeper than the tolerance: at 0 the package itself collides the
#: moment it moves (paper scene: r4c1 - r4c4 at 6e-5 s). Distances are exact to
#: 1e-10 m (``collision.geometry.CERTIFY_TOL``), so the tolerance must stand
#: clear of that; above it, what counts is the user's choice (at 1e-9 .. 1e-6 m
#: the stowed neighbours' presses through the compliant loop count, within 17 ms).
MIN_COLLISION_TOLERANCE = 1e-9
_WHY_TOLERANCE = ("panels touching in the stowed stacks are 0 apart, so a smaller tolerance "
                  "takes the package for a collision")
#: Densest fluid the drag model takes, kg/m^3: it has no added mass, which in a
#: gas is a few % of a panel's mass (air on the paper's 20 g panels: about 3 %) but in a
#: liquid several times it.
MAX_FLUID_DENSITY = 100.0
_WHY_FLUID = ("a gas (Venus's surface: 65 kg/m^3); a liquid's added mass, "
              "which the model leaves out, would outweigh the panels")


# --- field parsers: each takes (value, path) and returns the parsed value or raises ---

def _type_name(v):
    return type(v).__name__


_YAML12_FLOAT = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")


def number(low=None, high=None, low_open=False, allow_inf=False, why="", floor=None):
    """A number parser; ``high`` and ``floor`` (smallest accepted value above
    ``low``) are sanity limits, ``why`` says why (in the message)."""
    def parse(v, path):
        # PyYAML follows YAML 1.1, which reads 1.0e6 (no exponent sign) as a string.
        if isinstance(v, str) and _YAML12_FLOAT.match(v.strip()):
            v = float(v)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise SceneError(path, f"expected a number, got {_type_name(v)} {shown(v)}")
        try:
            v = float(v)
        except OverflowError:  # an integer beyond any float
            raise SceneError(path, f"expected a finite number, got {shown(v)}") from None
        if math.isnan(v) or (math.isinf(v) and not allow_inf):
            raise SceneError(path, f"expected a finite number, got {v}")
        if low is not None and (v <= low if low_open else v < low):
            raise SceneError(path, f"expected a number {'>' if low_open else '>='} {low:g}, got {v:g}")
        if floor is not None and v < floor:
            raise SceneError(path, f"expected a number >= {floor:g}, got {v:g}"
                                   + (f" (limit: {why})" if why else ""))
        if high is not None and v > high:
            raise SceneError(path, f"expected a number <= {high:g}, got {v:g}"
                                   + (f" (limit: {why})" if why else ""))
        return v
    parse.describe = ("number" + (f" {'>' if low_open else '>='} {low}" if low is not None else "")
                      + (f", <= {high:g}" if high is not None else ""))
    return parse


def integer(low=None, high=None, why=""):
    def parse(v, path):
        if isinstance(v, bool) or not isinstance(v, int):
            raise SceneError(path, f"expected an integer, got {_type_name(v)} {shown(v)}")
        if low is not None and v < low:
            raise SceneError(path, f"expected an integer >= {low}, got {shown(v)}")
        if high is not None and v > high:
            raise SceneError(path, f"expected an integer <= {high}, got {shown(v)}"
                                   + (f" (limit: {why})" if why else ""))
        return v
    parse.describe = ("integer" + (f" >= {low}" if low is not None else "")
                      + (f", <= {high}" if high is not None else ""))
    return parse


def boolean(v, path):
    if not isinstance(v, bool):
        raise SceneError(path, f"expected true or false, got {_type_name(v)} {shown(v)}")
    return v


boolean.describe = "true/false"


def choice(*options):
    def parse(v, path):
        if v not in options:
            raise SceneError(path, f"expected one of {', '.join(map(str, options))}, got {shown(v)}")
        return v
    parse.describe = " | ".join(options)
    return parse


def vector3(v, path):
    if not isinstance(v, (list, tuple)) or len(v) != 3:
        raise SceneError(path, f"expected a list of 3 numbers, got {shown(v)}")
    return tuple(number()(x, f"{path}[{i}]") for i, x in enumerate(v))


vector3.describe = "[x, y, z]"

_SIZE = number(0, 1e3, low_open=True, floor=1e-6, why=_WHY_SCALE)


def cell(v, path):
    if (not isinstance(v, (list, tuple)) or len(v) != 2
            or not all(isinstance(x, int) and not isinstance(x, bool) and x >= 1 for x in v)):
        raise SceneError(path, f"expected a cell [row, col] of integers >= 1, got {shown(v)}")
    return (v[0], v[1])


cell.describe = "[row, col]"


def mapping(v, path):
    if not isinstance(v, dict):
        raise SceneError(path, f"expected a mapping, got {_type_name(v)} {shown(v)}")
    return v


mapping.describe = "mapping"


def cell_list(v, path):
    if not isinstance(v, (list, tuple)):
        raise SceneError(path, f"expected a list of cells [row, col], got {shown(v)}")
    return tuple(cell(x, f"{path}[{i}]") for i, x in enumerate(v))


def cell_pairs(v, path):
    if not isinstance(v, (list, tuple)):
        raise SceneError(path, f"expected a list of cell pairs [[r, c], [r, c]], got {shown(v)}")
    out = []
    for i, pair in enumerate(v):
        if not isinstance(pair, (list, tuple)) or len(pair) != 2:
            raise SceneError(f"{path}[{i}]", f"expected a pair of cells, got {shown(pair)}")
        pair = tuple(sorted(cell(c, f"{path}[{i}][{j}]") for j, c in enumerate(pair)))
        if pair in out:  # the same hinge twice is a slip: which other one was meant?
            raise SceneError(f"{path}[{i}]", f"pair {[list(c) for c in pair]} is given twice "
                                             f"(first as {path}[{out.index(pair)}])")
        out.append(pair)
    return tuple(out)


def one_of(*parsers, describe):
    """First parser of ``parsers`` that accepts the value; else the error of one
    that took its shape and refused an item (its path names the item), else
    what was expected."""
    def parse(v, path):
        errors = []
        for p in parsers:
            try:
                return p(v, path)
            except SceneError as e:
                errors.append(e)
        for e in errors:
            if e.path != path:
                raise e
        raise SceneError(path, f"expected {describe}, got {shown(v)}") from errors[-1]
    parse.describe = describe
    return parse


def optional(parser):
    def parse(v, path):
        return None if v is None else parser(v, path)
    parse.describe = f"{getattr(parser, 'describe', '')} or null"
    return parse


def check_collision_tolerance(v, path):
    """``v`` if it is at least :data:`MIN_COLLISION_TOLERANCE`, else the one
    error naming ``path`` (the scene key, or the node parameter)."""
    if not v >= MIN_COLLISION_TOLERANCE:
        got = f"{v:g}" if isinstance(v, float) else shown(v)
        raise SceneError(path, f"expected a number >= {MIN_COLLISION_TOLERANCE:g}, got {got} "
                               f"(limit: {_WHY_TOLERANCE})")
    return v


def collision_tolerance(v, path):
    v = number(0.0, COLLISION_MARGIN, why=f"the collision check's broad phase computes pairs "
                                          f"only within {COLLISION_MARGIN:g} m")(v, path)
    return check_collision_tolerance(v, path)


collision_tolerance.describe = f"number >= {MIN_COLLISION_TOLERANCE:g}, <= {COLLISION_MARGIN:g}"


def hinge_stiffness_map(v, path):
    if not isinstance(v, dict):
        raise SceneError(path, f"expected a mapping hinge name -> stiffness, got {shown(v)}")
    return {str(k): number(0.0, 1e4, why=_WHY_STIFF)(x, f"{path}.{k}") for k, x in v.items()}


hinge_stiffness_map.describe = "{hinge name: N m/rad}"


def hinge_damping_map(v, path):
    if not isinstance(v, dict):
        raise SceneError(path, f"expected a mapping hinge name -> damping, got {shown(v)}")
    return {str(k): number(0.0, 1e4, why=_WHY_STIFF)(x, f"{path}.{k}") for k, x in v.items()}


hinge_damping_map.describe = "{hinge name: N m s/rad}"


def groups(v, path):
    if v in ("auto", "none"):
        return v
    if not isinstance(v, list) or not all(isinstance(g, list) for g in v):
        raise SceneError(path, f"expected auto, none or a list of lists of hinge names, got {shown(v)}")
    for i, g in enumerate(v):
        if not g:
            raise SceneError(f"{path}[{i}]", "a group needs at least one hinge")
    return tuple(tuple(str(h) for h in g) for g in v)


groups.describe = "auto | none | [[hinge, ...], ...]"


def spec(default, parse, unit="", doc=""):
    return field(default=default, metadata={"parse": parse, "unit": unit, "doc": doc})


# --- sections ---

@dataclass(frozen=True)
class ArraySection:
    rows: int = spec(None, integer(1, MAX_SIDE, _WHY_SIDE), "", "number of panel rows R")
    cols: int = spec(None, integer(1, MAX_SIDE, _WHY_SIDE), "", "number of panel columns C")
    length: float = spec(None, _SIZE, "m", "panel length a, along x (columns)")
    width: float = spec(None, _SIZE, "m", "panel width b, along y (rows)")
    thickness: float = spec(None, _SIZE, "m", "panel thickness t")
    mass: float = spec(None, optional(number(0, 1e6, low_open=True, floor=1e-9, why=_WHY_SCALE)), "kg",
                       "mass of one unit panel (give mass or density)")
    density: float = spec(None, optional(number(0, 1e6, low_open=True, floor=MIN_DENSITY,
                                                why=_WHY_DENSITY)), "kg/m^3",
                          "panel density (give mass or density)")

    @property
    def unit_mass(self) -> float:
        """Mass of one unit panel, kg."""
        if self.mass is not None:
            return self.mass
        return self.density * self.length * self.width * self.thickness


@dataclass(frozen=True)
class FoldSection:
    circuit: Any = spec(0, one_of(choice("auto"), integer(0), cell_list,
                                  describe="auto, a circuit index or a list of cells"),
                        "", "Hamiltonian circuit: index in panel-deploy fold's order, cells in "
                            "order, or auto (the best of a screening run of the first packing "
                            "circuits, panel-deploy fold --rank)")
    ground: Any = spec(None, optional(cell), "", "cell of the ground panel (default: first circuit cell)")
    merge: Any = spec("auto", one_of(choice("auto", "none"), cell_pairs,
                                     describe="auto, none or a list of cell pairs"),
                      "", "merge side-by-side panels: auto, none, or the cell pairs to merge")
    # what fold.circuit: auto chose and why, written with the index it resolved
    # to: read by people, never by a computation, so any mapping is accepted
    circuit_choice: Any = spec(None, optional(mapping), "",
                               "informational: how fold.circuit: auto chose the circuit "
                               "(written by the ranking)")


@dataclass(frozen=True)
class ScreeningSection:
    """How ``fold.circuit: auto`` and ``panel-deploy fold --rank`` screen the
    packing circuits (:mod:`panel_deploy.ranking`)."""

    # 8: measured with the paper's panels and springs (2 shared cores), 4 x 4 (all
    # 6) 2.2 s, 5 x 6 4.8 s, 6 x 6 8.9 s, 10 x 10 49 s (its first 8 packing circuits
    # are among its first 132; 4-7 s each, mostly building the 100-body model and
    # the collision check, the runs colliding by 0.05 s).
    candidates: int = spec(8, integer(1, 100000), "",
                           "packing circuits screened, the first in circuit index order")
    # 1 s: past the first collisions of the 4 x 4 to 6 x 6 circuits screened
    # (0.02-0.75 s with the paper's panels and springs), short against a full
    # deployment (the paper's array lies flat at ~1.6 s); a circuit still
    # unfolding then ranks by how close to flat it came.
    t_end: float = spec(1.0, number(0.0, 600.0, low_open=True), "s",
                        "screening end time (at most simulation.t_end)")
    # 1e-4: what the paper scene's stiffness search evaluates at; 1e-3 failed the
    # energy balance (1 %) on 3 of 16 of the 3 x 4 .. 4 x 5 circuits, 1e-4 on 1.
    rtol: float = spec(1.0e-4, number(0.0, 1.0, low_open=True), "",
                       "screening relative tolerance (at least simulation.rtol; atol keeps "
                       "the scene's ratio to rtol)")
    damping_ratio: Any = spec(None, optional(number(0.0, 1e3, why=_WHY_STIFF)), "s",
                              "c/k of every hinge in the screening runs (default "
                              "hinges.damping_ratio), e.g. the top of the search's c/k bounds")


@dataclass(frozen=True)
class HingeSection:
    stiffness: float = spec(0.1, number(0.0, 1e4, why=_WHY_STIFF), "N m/rad",
                            "k of every hinge unless overridden")
    damping_ratio: float = spec(0.043, number(0.0, 1e3, why=_WHY_STIFF), "s",
                                "c/k (Rayleigh damping: c follows k)")
    overrides: dict = spec(None, optional(hinge_stiffness_map), "N m/rad", "k of named hinges")
    damping_overrides: dict = spec(None, optional(hinge_damping_map), "N m s/rad",
                                   "c of named hinges (one spring), instead of damping_ratio * k")
    groups: Any = spec("auto", groups, "", "hinges sharing one stiffness: auto (mirror symmetry), none, or lists")


@dataclass(frozen=True)
class ContactSection:
    k_s: float = spec(1000.0, number(0, 1e9, low_open=True, why=_WHY_STIFF), "N m/rad",
                      "joint-limit contact stiffness, Eq. (4)")
    c_s: float = spec(0.5, number(0.0, 1e6, why=_WHY_STIFF), "N m s/rad",
                      "joint-limit contact damping, Eq. (4)")
    stop_ramp: float = spec(0.0, number(0.0, 0.01, why="deeper, the ramp is the stop: its overshoot "
                                                     "is milliradians"), "rad",
                            "depth past a joint limit over which k_s and c_s come in smoothly "
                            "(0: at once, Eq. 4)")
    panels: bool = spec(True, boolean, "", "contact between unhinged panels")
    k_p: float = spec(1.0e7, number(0, 1e11, low_open=True, why=_WHY_STIFF), "N/m",
                      "normal stiffness of one panel-to-panel contact pressed evenly")
    c_p: float = spec(280.0, number(0.0, 1e8, why=_WHY_STIFF), "N s/m",
                      "normal damping of one panel-to-panel contact")
    pressure: bool = spec(False, boolean, "", "faces push by a pressure over their overlap, in "
                          "proportion to depth (continuous in the pose), not by springs at its corners")
    friction: float = spec(0.0, number(0.0, 10.0, why="Coulomb coefficients of solids are below ~2"), "",
                           "Coulomb friction coefficient of panel-to-panel contact (0: the panels "
                           "slide freely, and the friction code is left out)")
    friction_speed: float = spec(1.0e-3, number(0.0, 10.0, low_open=True, floor=1e-6,
                                                why="slower, the friction is as stiff as the contact "
                                                    "and the steps follow it"),
                                 "m/s", "slip speed below which friction is viscous (its force "
                                        "mu N v / sqrt(v^2 + friction_speed^2))")
    reach: Any = spec(None, optional(number(0.0, 100.0)), "m",
                      "only unhinged panels this close in the stowed stacks get a contact "
                      "(default: every unhinged pair)")


@dataclass(frozen=True)
class ClosureSection:
    method: str = spec("penalty", choice("penalty", "exact"), "",
                       "penalty: the paper's Eq. (5) springs; exact: Lagrange multipliers")
    cut_hinge: Any = spec(None, optional(one_of(cell_pairs, describe="a list of cell pairs")), "",
                          "segments of the hinges to cut, one per loop (default: farthest from ground)")
    k_M: float = spec(1.0e6, number(0, 1e11, low_open=True, why=_WHY_STIFF), "N/m",
                      "penalty stiffness at M (x, y, z)")
    c_M: float = spec(280.0, number(0.0, 1e8, why=_WHY_STIFF), "N s/m", "penalty damping at M")
    k_N: float = spec(1.0e6, number(0, 1e11, low_open=True, why=_WHY_STIFF), "N/m",
                      "penalty stiffness at N (2 directions)")
    c_N: float = spec(280.0, number(0.0, 1e8, why=_WHY_STIFF), "N s/m", "penalty damping at N")
    baumgarte: float = spec(1.0e-3, number(0, 10.0, low_open=True, floor=1e-6,
                                           why="the stabilisation's 1/T^2 term must stay far "
                                               "from overflow and the run's time scale"),
                            "s", "exact: constraint stabilisation time constant")
    regularisation: float = spec(1.0e-10, number(0.0, 1.0, why="a relative term: 1 already "
                                                               "doubles the solve's diagonal"),
                                 "", "exact: relative Tikhonov term of the multiplier solve")


@dataclass(frozen=True)
class SimulationSection:
    t_end: float = spec(1.0, number(0, 600.0, low_open=True, why="arrays deploy in seconds; "
                                                                  "ten minutes is far beyond"), "s",
                        "end time")
    method: str = spec("RK23", choice(*INTEGRATORS), "",
                       "integrator: scipy's RK23 ... LSODA, the compiled dopri5, tsit5 or "
                       "ros34pw2, or compiled (tsit5 or ros34pw2, whichever suits the start state)")
    rtol: float = spec(1.0e-6, number(0, low_open=True), "", "relative tolerance")
    atol: float = spec(1.0e-8, number(0, low_open=True, floor=1e-12,
                                      why="far below any hinge's accuracy, and near double "
                                          "precision, where the steps stall"),
                       "", "absolute tolerance")
    max_step: float = spec(math.inf, number(0, low_open=True, allow_inf=True), "s", "largest step")
    samples: int = spec(301, integer(3, MAX_SAMPLES, "memory: every sample stores the pose and "
                                                     "velocity of every body"), "",
                        "number s of evenly spaced sample instants t_j")
    events: bool = spec(True, boolean, "", "locate joint-limit contact switches as solver events "
                        "(not with a contact.stop_ramp: a ramped stop has no jump to locate)")
    flat_tolerance: float = spec(0.05, number(0, low_open=True), "rad",
                                 "the array counts as flat (deployed) at the first sample where "
                                 "every hinge has |theta| <= this")


@dataclass(frozen=True)
class CollisionSection:
    tolerance: float = spec(1.0e-4, collision_tolerance, "m",
                            "interference depth beyond which touching panels count as colliding")
    refine: bool = spec(True, boolean, "", "refine between samples so that no collision is missed")
    impact_speed: float = spec(IMPACT_SPEED, number(0.0, 100.0, low_open=True), "m/s",
                               "panels in contact that meet this fast or faster along the normal "
                               "collide (an impact the contact absorbed); slower, they press, "
                               "and only interference deeper than the tolerance collides")
    noise: float = spec(0.0, number(0.0, 0.1, why="encoders that noisy locate nothing"), "rad",
                        "standard deviation of measured angles (encoders); above 0 a collision "
                        "must be deeper than the noise can fake, and approaching; 0: a "
                        "simulated stream")
    speed_interval: float = spec(None, optional(number(0.0, 10.0)), "s",
                                 "spacing of Eq. 7's two distances on a fixed grid; 0: the "
                                 "stream's own samples; null: the scene's sample interval")
    stamps: str = spec("header", choice("header", "receipt"), "",
                       "a joint state's time: header (its header.stamp) or receipt (when it "
                       "arrived: the node's receipt, a recording's log time), for drivers "
                       "that leave stamps unfilled")


@dataclass(frozen=True)
class AirSection:
    density: float = spec(0.0, number(0.0, MAX_FLUID_DENSITY, why=_WHY_FLUID), "kg/m^3",
                          "density of the still air around the array; 0: no air (the paper's "
                          "model; sea level: 1.2)")
    drag_coefficient: float = spec(1.17, number(0.0, 5.0, why="a flat plate normal to the "
                                                              "flow has 1.17 (square) to 2 (strip)"),
                                   "", "C_d of the panel faces: pressure -1/2 rho C_d |v_n| v_n "
                                       "on the normal velocity v_n of each face point")


def _bounds(v, path):
    if not isinstance(v, (list, tuple)) or len(v) != 2:
        raise SceneError(path, f"expected [lower, upper], got {shown(v)}")
    lo, hi = (number(0.0)(x, f"{path}[{i}]") for i, x in enumerate(v))
    if lo > hi:
        raise SceneError(path, f"lower bound {lo:g} is above upper bound {hi:g}")
    return (lo, hi)


_bounds.describe = "[lower, upper]"


@dataclass(frozen=True)
class OptimisationSection:
    p: float = spec(1.0, number(0.0), "s/m", "weight of the approach speed v in f = p v - q d")
    q: float = spec(10.0, number(0.0), "1/m", "weight of the smallest distance d (earned only by a collision-free run that reaches flat)")
    flat_weight: float = spec(1.0, number(0.0), "1/rad", "weight of how far from flat the run stays (its closest approach: the smallest, over samples, of the largest |theta|)")
    bounds: tuple = spec((0.001, 0.2), _bounds, "N m/rad", "lower and upper stiffness bound")
    k0: float = spec(0.1, number(0, low_open=True), "N m/rad", "starting stiffness K_0")
    damping_ratio_bounds: tuple = spec(None, optional(_bounds), "s",
                                       "lower and upper c/k when one damping ratio for all hinges "
                                       "(a lubricant, paper section 5) is searched for too, from "
                                       "hinges.damping_ratio, and the result centred in the c/k "
                                       "range where its K is feasible; null: c/k stays fixed")
    method: str = spec("local", choice("local", "global"), "", "local (scipy minimize) or global (differential evolution)")
    restarts: int = spec(3, integer(0), "", "restarts from new K_0 while collisions remain")
    max_evaluations: int = spec(200, integer(1), "", "simulation budget")
    workers: int = spec(0, integer(0), "", "parallel workers (0: all cores)")
    seed: int = spec(0, integer(0), "", "random seed for restarts and global search")
    # 3: the 8 x 8 screening's top three were within 0.01 rad of flat at 8 s, and
    # its first gave no design that the re-check passed (docs/findings.md 4.8)
    circuits: int = spec(3, integer(1), "",
                         "with fold.circuit: auto, the best-ranked circuits optimised in turn "
                         "until one gives a design that the re-check passes")
    rtol: float = spec(None, optional(number(0, low_open=True)), "",
                       "simulation.rtol during the search (atol scaled alike; default simulation.rtol); "
                       "the optimum is re-checked at simulation.rtol / 10")
    refine: bool = spec(None, optional(boolean), "",
                        "collision.refine during the search (default collision.refine); "
                        "the optimum is re-checked with collision.refine")


@dataclass(frozen=True)
class Scene:
    """A validated scene.

    ``source`` is the file it came from, if any; ``data`` the mapping it was
    validated from (what a saved trajectory stores to rebuild the model).
    """

    array: ArraySection
    fold: FoldSection = FoldSection()
    screening: ScreeningSection = ScreeningSection()
    hinges: HingeSection = HingeSection()
    contact: ContactSection = ContactSection()
    closure: ClosureSection = ClosureSection()
    gravity: tuple = (0.0, -9.81, 0.0)
    simulation: SimulationSection = SimulationSection()
    collision: CollisionSection = CollisionSection()
    air: AirSection = AirSection()
    optimisation: OptimisationSection = OptimisationSection()
    name: str = ""
    description: str = ""
    source: str | None = None
    data: dict = field(default=None, compare=False, repr=False)

    def replace(self, **sections) -> "Scene":
        return replace(self, **sections)


SECTIONS = {
    "array": ArraySection, "fold": FoldSection, "screening": ScreeningSection,
    "hinges": HingeSection,
    "contact": ContactSection, "closure": ClosureSection,
    "simulation": SimulationSection, "collision": CollisionSection, "air": AirSection,
    "optimisation": OptimisationSection,
}
TOP_LEVEL = {"gravity": (vector3, "m/s^2", "gravity in the flat array frame (y towards row 1)"),
             "name": (None, "", "scene name"), "description": (None, "", "free text"),
             # where the scene's values came from (a calibration's figures): read by
             # people, never by a computation, so any mapping is accepted as it is
             "calibration": (None, "", "informational: how values were calibrated (any mapping)")}


def parse_section(cls, data, path):
    """The section ``cls`` of a scene from its mapping ``data`` (None: every
    key's default), each key parsed and checked as in a scene file.

    Raises
    ------
    SceneError
        Naming ``path.<key>`` and what was wrong.
    """
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise SceneError(path, f"expected a mapping, got {_type_name(data)} {shown(data)}")
    known = {f.name: f for f in fields(cls)}
    for key in data:
        if key not in known:
            raise SceneError(f"{path}.{key}", f"unknown key (expected one of {', '.join(known)})")
    values = {}
    for name, f in known.items():
        if name in data:
            values[name] = f.metadata["parse"](data[name], f"{path}.{name}")
    return cls(**values)


def _check_required(section, path, names):
    for n in names:
        if getattr(section, n) is None:
            raise SceneError(f"{path}.{n}", "required key is missing")


def scene_from_dict(data: dict, source: str | None = None) -> Scene:
    """Validate a scene mapping (as read from YAML) and return a :class:`Scene`.

    Raises
    ------
    SceneError
        Naming the key path of the first problem found.
    """
    if not isinstance(data, dict):
        raise SceneError("", f"a scene must be a mapping of sections, got {_type_name(data)}")
    for key in data:
        if key not in SECTIONS and key not in TOP_LEVEL:
            raise SceneError(key, f"unknown section (expected one of {', '.join([*SECTIONS, *TOP_LEVEL])})")
    if "array" not in data:
        raise SceneError("array", "required section is missing")
    sections = {name: parse_section(cls, data.get(name), name) for name, cls in SECTIONS.items()}
    arr = sections["array"]
    _check_required(arr, "array", ("rows", "cols", "length", "width", "thickness"))
    if (arr.mass is None) == (arr.density is None):
        raise SceneError("array.mass", "give exactly one of array.mass and array.density")
    if arr.mass is not None and arr.mass < MIN_DENSITY * arr.length * arr.width * arr.thickness:
        raise SceneError("array.mass", f"{arr.mass:g} kg in a {arr.length:g} x {arr.width:g} x "
                                       f"{arr.thickness:g} m panel is "
                                       f"{arr.mass / (arr.length * arr.width * arr.thickness):.3g} "
                                       f"kg/m^3; expected >= {MIN_DENSITY:g} (limit: {_WHY_DENSITY})")
    if (arr.rows * arr.cols) % 2:
        raise SceneError("array", f"{arr.rows} x {arr.cols} = {arr.rows * arr.cols} panels is odd: "
                                  "two equal stacks need an even panel count")
    opt = sections["optimisation"]
    lo, hi = opt.bounds
    if not lo <= opt.k0 <= hi:
        raise SceneError("optimisation.k0", f"{opt.k0:g} is outside bounds [{lo:g}, {hi:g}]")
    if opt.damping_ratio_bounds is not None:
        lo, hi = opt.damping_ratio_bounds
        beta = sections["hinges"].damping_ratio
        if not 0 < lo < hi:
            raise SceneError("optimisation.damping_ratio_bounds",
                             f"expected 0 < lower < upper (s, searched in log scale), got "
                             f"[{lo:g}, {hi:g}]")
        if not lo <= beta <= hi:
            raise SceneError("optimisation.damping_ratio_bounds",
                             f"the search starts from hinges.damping_ratio = {beta:g} s, which is "
                             f"outside [{lo:g}, {hi:g}]")
    gravity = vector3(data["gravity"], "gravity") if "gravity" in data else Scene.gravity
    for i, g in enumerate(gravity):
        if abs(g) > 9810.0:
            raise SceneError(f"gravity[{i}]", f"expected |g| <= 9810 m/s^2, got {g:g} "
                                              f"(limit: {_WHY_G})")
    sim = sections["simulation"]
    if sim.t_end / sim.max_step > STEP_BUDGET:
        raise SceneError("simulation.max_step", f"t_end / max_step = {sim.t_end / sim.max_step:.3g} "
                                                f"steps is above the step budget of {STEP_BUDGET} "
                                                "(it would run for hours and then fail)")
    for key in ("name", "description"):
        if key in data and not isinstance(data[key], str):
            raise SceneError(key, f"expected a string, got {_type_name(data[key])}")
    if "calibration" in data:
        mapping(data["calibration"], "calibration")
    return Scene(**sections, gravity=gravity, name=data.get("name", ""),
                 description=data.get("description", ""), source=source, data=data)


def resolve_scene(name: str) -> Path:
    """A scene path, or the name of a scene shipped with the package (``paper_4x4``)."""
    path = Path(name)
    try:
        if path.exists() or path.suffix:
            return path
    except OSError:  # a name too long: reading it says so
        return path
    for base in (Path(__file__).resolve().parent.parent / "config" / "scenes",
                 Path(sys.prefix) / "share" / "panel_deploy" / "config" / "scenes"):
        if (base / f"{name}.yaml").exists():
            return base / f"{name}.yaml"
    return path


def load_scene(path, overrides=()) -> Scene:
    """Read and validate a scene YAML file.

    Parameters
    ----------
    path : str or Path
    overrides : sequence of str
        ``"key.path=value"`` items applied to the file's mapping before
        validation, the value read as YAML (``gravity=[0, 0, 0]``,
        ``simulation.t_end=3``); see :func:`apply_overrides`.

    Raises
    ------
    SceneError
        If the file is missing or unreadable, is not valid YAML, or fails
        validation (overrides included); the message names the file and the
        key path.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise SceneError(str(path), "scene file not found") from None
    except (OSError, UnicodeDecodeError) as e:
        raise SceneError(str(path), f"cannot read scene file ({getattr(e, 'strerror', None) or e})") from None
    from .validate import load_yaml, yaml_problem
    try:
        data = load_yaml(text)
    except yaml.YAMLError as e:
        raise SceneError(str(path), f"malformed YAML {yaml_problem(e)}") from None
    data = apply_overrides(data, overrides)  # its errors name the --set item, not the file
    try:
        return scene_from_dict(data, source=str(path))
    except SceneError as e:
        if _overridden(e.path, overrides):  # a mistake on the command line, not in the file
            raise SceneError(f"--set {e.path}", e.reason) from None
        raise SceneError(f"{path.name}: {e.path}" if e.path else path.name, e.reason) from None


def _overridden(key_path, overrides) -> bool:
    """Whether ``key_path`` (``simulation.t_end``, ``gravity[0]``) was set by one of ``overrides``."""
    if not key_path:
        return False
    for item in overrides:
        key = str(item).partition("=")[0].strip()
        if key_path == key or key_path.startswith((key + ".", key + "[")) \
                or key.startswith(key_path + "."):
            return True
    return False


def apply_overrides(data, overrides) -> dict:
    """A copy of the scene mapping ``data`` with ``"key.path=value"`` items set.

    The value is parsed as YAML, so numbers, lists and mappings keep their
    type; sections that are missing are created. Validation is left to
    :func:`scene_from_dict`, which names the key of a bad value.

    Raises
    ------
    SceneError
        If an item has no ``=`` or an empty key, its value is not valid YAML,
        or its key path runs through a value that is not a mapping.
    """
    data = copy.deepcopy(data) if data is not None else {}
    for item in overrides:
        key, sep, text = str(item).partition("=")
        key = key.strip()
        if not sep or not key or any(not part for part in key.split(".")):
            raise SceneError(str(item), "expected an override KEY.PATH=VALUE, "
                                        "e.g. simulation.t_end=3")
        from .validate import load_yaml, yaml_problem
        try:
            value = load_yaml(text)
        except yaml.YAMLError as e:
            raise SceneError(f"--set {key}", f"value {shown(text)} is not valid YAML "
                                             f"({yaml_problem(e)})") from None
        *parents, last = key.split(".")
        node = data
        for part in parents:
            node = node.setdefault(part, {}) if isinstance(node, dict) else None
        if not isinstance(node, dict):
            raise SceneError(".".join(parents) or key, f"cannot set {key}: not a mapping")
        node[last] = value
    return data


def describe_schema() -> str:
    """The schema as a text table: key path, type, unit, default, meaning."""
    rows = []
    for name, cls in SECTIONS.items():
        for f in fields(cls):
            parse = f.metadata["parse"]
            rows.append((f"{name}.{f.name}", getattr(parse, "describe", ""), f.metadata["unit"],
                         "required" if f.default is None and name == "array" and f.name not in ("mass", "density")
                         else repr(f.default), f.metadata["doc"]))
    rows.append(("gravity", "[x, y, z]", "m/s^2", repr(Scene.gravity), TOP_LEVEL["gravity"][2]))
    rows.append(("calibration", "mapping", "", "None", TOP_LEVEL["calibration"][2]))
    widths = [max(len(r[i]) for r in rows) for i in range(4)]
    return "\n".join("  ".join(r[i].ljust(widths[i]) for i in range(4)) + "  " + r[4] for r in rows)

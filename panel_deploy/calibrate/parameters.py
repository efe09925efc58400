"""What a calibration fits: hinge stiffness k and damping c as scale factors
of the scene's values (one each, or one per stiffness group), and the drag
coefficient C_d of the panel faces; how a set of values becomes a model.

A scale factor multiplies every k_i (or c_i) of its hinges: ``k_i = s_k
k_i,scene``, ``c_i = s_c c_i,scene``. Without a damping factor c follows k
(``c_i = s_k c_i,scene``), as everywhere in the package (Rayleigh damping,
paper section 3.3). The fit works on their logarithms, so that every value
stays positive and a factor's steps are relative.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import ModelError, SceneError
from ..model import AirParameters, Model

#: The parameter kinds ``--fit`` names.
KINDS = ("damping", "stiffness", "drag")
#: How k and c are grouped: one factor for all hinges, or one per stiffness group.
PER = ("scale", "group")
#: Bounds of a scale factor: a fit that leaves them has found no hinge of this array.
SCALE_BOUNDS = (0.02, 50.0)
#: Bounds of C_d, as the scene's ``air.drag_coefficient`` (above 0: fitted in log space).
DRAG_BOUNDS = (1e-3, 5.0)
#: C_d a fit starts from when the scene's is 0 (a square plate normal to the flow).
DRAG_START = 1.17


@dataclass(frozen=True)
class Parameters:
    """The fitted parameters of one calibration and the model they act on.

    Attributes
    ----------
    model : Model
        The scene's model: every factor 1 and C_d the scene's reproduce it.
    fit : tuple of str
        Kinds fitted, in :data:`KINDS` order.
    per : str
    names : tuple of str
        One per parameter: ``stiffness``, ``damping``, ``drag``, or per group
        ``stiffness[<first hinge of the group>]``.
    kinds : tuple of str
        The kind of every parameter.
    groups : tuple of tuple of int
        Hinge indices of every parameter (all hinges for a scale factor and
        for C_d).
    start, nominal : (p,) ndarray
        Where the fit starts, and the values that reproduce the scene
        (1 for a factor, the scene's C_d).
    lower, upper : (p,) ndarray
        Bounds of the values.
    """

    model: Model
    fit: tuple
    per: str
    names: tuple
    kinds: tuple
    groups: tuple
    start: np.ndarray
    nominal: np.ndarray
    lower: np.ndarray
    upper: np.ndarray

    def without(self, names) -> Parameters:
        """These parameters less those named in ``names``, which then stay at
        the scene's values (factor 1)."""
        keep = [i for i, name in enumerate(self.names) if name not in names]

        def pick(seq):
            return tuple(seq[i] for i in keep)

        return replace(self, names=pick(self.names), kinds=pick(self.kinds),
                       groups=pick(self.groups), start=self.start[keep],
                       nominal=self.nominal[keep], lower=self.lower[keep], upper=self.upper[keep])

    def model_at(self, values) -> Model:
        """The model with parameter ``values`` (factors, C_d) applied."""
        values = np.asarray(values, dtype=float)
        n = len(self.model.hinges)
        factor = {"stiffness": np.ones(n), "damping": None}
        model = self.model
        for kind, group, value in zip(self.kinds, self.groups, values):
            if kind == "drag":
                model = replace(model, air=AirParameters(model.air.density, float(value)))
                continue
            if factor[kind] is None:
                factor[kind] = np.ones(n)
            factor[kind][list(group)] = value
        k = np.array([h.k for h in self.model.hinges])
        c = np.array([h.c for h in self.model.hinges])
        s_c = factor["stiffness"] if factor["damping"] is None else factor["damping"]
        return model.with_stiffness(k * factor["stiffness"], c * s_c)


def parameters(model: Model, fit, per: str = "scale") -> Parameters:
    """The :class:`Parameters` of fitting ``fit`` (kinds of :data:`KINDS`)
    to ``model``, ``per`` "scale" (one factor each) or "group" (one per
    ``model.hinge_groups`` group).

    Raises
    ------
    ModelError
        An unknown kind or ``per``, or nothing to fit.
    SceneError
        ``drag`` in a scene without air (``air.density`` 0: C_d then acts on nothing).
    """
    unknown = [kind for kind in fit if kind not in KINDS]
    if unknown or not fit:
        raise ModelError(f"fit: expected some of {', '.join(KINDS)}, got {list(fit)}")
    if per not in PER:
        raise ModelError(f"per: expected one of {', '.join(PER)}, got {per!r}")
    if "drag" in fit and not model.air.density > 0:
        raise SceneError("air.density", "is 0 (no air): there is no drag to fit; give the "
                                        "density of the air the array deployed in "
                                        "(--set air.density=1.2)")
    everything = tuple(range(len(model.hinges)))
    groups = (model.hinge_groups or tuple((i,) for i in everything)) if per == "group" else (everything,)
    rows = []  # (name, kind, hinges, start, nominal) of every parameter
    for kind in (k for k in KINDS if k in fit):
        if kind == "drag":
            scene_cd = model.air.drag_coefficient
            rows.append((kind, kind, everything, scene_cd if scene_cd > 0 else DRAG_START, scene_cd))
            continue
        rows += [(kind if per == "scale" else f"{kind}[{model.hinges[group[0]].name}]", kind,
                  group, 1.0, 1.0) for group in groups]
    names, kinds, members, start, nominal = zip(*rows)
    bounds = np.array([DRAG_BOUNDS if kind == "drag" else SCALE_BOUNDS for kind in kinds])
    return Parameters(model, tuple(k for k in KINDS if k in fit), per, names, kinds, members,
                      np.clip(start, bounds[:, 0], bounds[:, 1]), np.array(nominal),
                      bounds[:, 0], bounds[:, 1])

"""The arrays one run's right-hand side fills at every evaluation on the O(n)
path (:func:`.kernels.rhs`), allocated once per run (:func:`allocate`), held
by one :class:`Buffers` object.

One object, not a tuple of the arrays: a compiled function counts a
reference on every array of a tuple it takes, at each call, where it holds
an object by one count. With the ~30 arrays as a tuple beside the candidate
list the paper scene's evaluation took 3.8 us, against 3.1 us with none
(docs/findings.md 5). An allocation in the compiled right-hand side costs
its malloc and free at every evaluation.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.experimental import structref

from ._jit import FLOAT_MATH

#: The arrays, in the order :class:`Buffers` takes them; (n,) is per joint,
#: (mc,) per exact-closure constraint (5 per cut hinge):
#: :func:`.kernels.kinematics_into`'s R (n + 1, 3, 3), p, w, vo (n + 1, 3)
#: and S (n, 6); :func:`.kernels.body_inertias_into`'s Jb (n, 3, 3) and hb
#: (n, 3); :func:`.kernels._bias`'s f and acc (n + 1, 6) and Q (n,);
#: :func:`.articulated.factor_into`'s IA (n, 21), U (n, 6) and D (n,), and
#: its armature (n, zeros); ``closure``, the exact closure's tuple:
#: :func:`.closure.closure_jacobian_into`'s c (mc,), J (mc, n), gamma (mc,)
#: and work (6, n), then :func:`.closure.articulated_closure`'s rows and
#: innovations (1 + mc, n), pass work (1 + mc, n + 1, 6), 1 / D (n,),
#: J M^-1 J^T and its factor (mc, mc), J M^-1 Q, lam and J omega (mc,).
FIELDS = ("R", "p", "w", "vo", "S", "Jb", "hb", "f", "acc", "Q", "IA", "U", "D", "armature", "closure")


@structref.register
class BuffersType(types.StructRef):
    """numba's type of :class:`Buffers`."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class Buffers(structref.StructRefProxy):
    """The right-hand side's arrays (:data:`FIELDS`), mutable scratch of one
    run, never shared between runs."""


structref.define_proxy(Buffers, BuffersType, list(FIELDS))


@njit(cache=True, **FLOAT_MATH)
def allocate(n, mc):
    """:class:`Buffers` for n joints and mc exact-closure constraints (n = mc
    = 0 where the dense path runs, which does not use them)."""
    closure = (np.empty(mc), np.empty((mc, n)), np.empty(mc), np.empty((6, n)),
               np.empty((1 + mc, n)), np.empty((1 + mc, n)), np.empty((1 + mc, n + 1, 6)),
               np.empty(n), np.empty((mc, mc)), np.empty(mc), np.empty((mc, mc)), np.empty(mc),
               np.empty(mc))
    return Buffers(np.empty((n + 1, 3, 3)), np.empty((n + 1, 3)), np.empty((n + 1, 3)),
                   np.empty((n + 1, 3)), np.empty((n, 6)), np.empty((n, 3, 3)), np.empty((n, 3)),
                   np.empty((n + 1, 6)), np.empty((n + 1, 6)), np.empty(n), np.empty((n, 21)),
                   np.empty((n, 6)), np.empty(n), np.zeros(n), closure)

"""The numba options of every dynamics kernel, in one place.

``FLOAT_MATH`` is passed to each ``@njit`` of the modules of
:mod:`panel_deploy.dynamics` (the right-hand side :mod:`.kernels` and its parts,
:mod:`.articulated`, :mod:`.stiff`, :mod:`.rosenbrock` and :mod:`.integrate`):

- ``fastmath={"contract"}``: LLVM may fuse a multiply and an add into one
  FMA, rounded once instead of twice, so each fused operation is as accurate
  or more. No other fast-math flag: the loops' tests for NaN and inf must
  stay, and reassociation would let the compiler reorder sums. It makes 10 x 10
  (exact closure, 0.2 s) 10-14 % faster an evaluation; trajectories change
  by rounding.
- ``error_model="numpy"``: a float division by zero gives inf or NaN, as in
  numpy, which the loops report as a non-finite state (``Status.NON_FINITE``),
  instead of a check before every division that raises ZeroDivisionError
  (3 % of an evaluation).

This file is one of ``_numba_cache.KERNEL_SOURCES``: numba keys its cache by
signature, not by these options, so a change here must recompile the kernels.

Importing it puts the compile notice in place
(:func:`panel_deploy._numba_cache.announce_compilation`): every dynamics kernel
module imports this one (the collision kernels theirs through the dynamics),
so the notice is there before anything compiles.
"""

from .._numba_cache import announce_compilation

announce_compilation()

FLOAT_MATH = {"fastmath": {"contract"}, "error_model": "numpy"}

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

The kernels that the right-hand side and the structured Rosenbrock step
call and that take arrays, the packed model (:class:`.pack.Packed`, 24
arrays) above all, are ``inline="always"`` (the tree's passes, the
closure's, the panel contacts' and their boxes' geometry in
:mod:`panel_deploy.boxes`): at every call that LLVM does not inline, numba
increments and decrements the reference count of each array argument, two
atomic operations an array, and LLVM inlines only small callees. numba's own
inlining puts the callee's body in the caller's, where numba's
reference-count pruning removes most of them, not all (with the right-hand
side's arrays allocated once per run, those left still took 10 % of an
evaluation: docs/findings.md 5). Measured with perf on 10 x 10
circuit 8 (exact closure, 0-0.2 s): ``NRT_incref`` and ``NRT_decref`` took
14 % of the run and 23 % of an evaluation in the stowed stacks, where each
touching pair's geometry made a dozen calls. With the inlining the window
takes 0.43 s against 0.55 s (the same steps and evaluations), an evaluation
21 us against 23 us at 0.1 s and 58 us against 80 us in the stowed stacks.
The price is compile time: every kernel that calls the right-hand side
compiles its own copy of it, and ``_precompile`` takes 310-330 s against
136 s.

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

"""Stiffness optimisation (paper section 3.3): choose hinge springs K so that
the array deploys without collision and reaches flat.

Public API::

    optimise(model, scene, *, k0=None, groups=None, workers=None, dask_address=None, progress=None, ...)
        -> OptimisationResult
    evaluate(model, k, scene, *, c=None) -> Evaluation
    objective(outcome, p, q, flat_weight) -> float
    save_result(result, path, scene_name="", extra=None) / load_stiffness(path, model)
    snap_to_springs(k, springs, *, max_parallel=2, zero_ratio=10.0, mode="up")
    verify(model, k, scene, *, tighten=10.0, refine=2) -> Evaluation
    tolerance_check(model, k, scene, *, n=20, stiffness_tol=0.05, damping_tol=0.05)
"""

from .evaluate import FLAT_TOLERANCE, Evaluation, Outcome, damping_ratio, evaluate, objective, run_deployment
from .io import load_damping, load_hinges, load_stiffness, result_to_dict, save_result
from .manufacture import SpringAssignment, ToleranceReport, snap_to_springs, soft_hinges, tolerance_check, verify
from .problem import StiffnessProblem
from .search import OptimisationResult, Progress, optimise, print_progress

__all__ = [
    "FLAT_TOLERANCE", "Evaluation", "OptimisationResult", "Outcome", "Progress", "SpringAssignment",
    "StiffnessProblem", "ToleranceReport", "damping_ratio", "evaluate", "load_damping",
    "load_hinges", "load_stiffness", "objective", "optimise", "print_progress", "result_to_dict",
    "run_deployment", "save_result", "snap_to_springs", "soft_hinges", "tolerance_check", "verify",
]

"""Deployment dynamics of a panel array: compiled recursive multibody kernels,
penalty or exact loop closure, scipy or compiled integrators.

``simulate(model, settings, state=None) -> SimulationResult``, or the same run
(bit for bit) in blocks of samples with ``simulate_segments`` (for consumers
that stream it or stop early); reports from a result: ``hinge_release_report``, ``dynamics_summary``,
``energy_balance_error``.
"""

from .report import dynamics_summary, energy_balance_error, hinge_release_report
from .result import SimulationResult, Status
from .simulate import default_gap_limit, simulate, simulate_segments

__all__ = ["SimulationResult", "Status", "default_gap_limit", "dynamics_summary",
           "energy_balance_error", "hinge_release_report", "simulate", "simulate_segments"]

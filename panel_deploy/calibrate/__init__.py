"""Calibration of a scene from recorded deployments (ROS-agnostic core of
``panel-deploy calibrate``): hinge damping and stiffness and the drag of
the panel faces fitted to recorded joint states, with their uncertainty.

- :mod:`.data`: a recording's measured hinges, checked to be worth fitting;
- :mod:`.parameters`: what is fitted and how values become a model;
- the simulated angles of the measured hinges at any time come from
  :mod:`panel_deploy.dynamics.hinge_trajectory` (``record.compare`` uses them too);
- :mod:`.residuals`: weighted residuals and their Jacobian;
- :mod:`.fit`: the least-squares fit (:func:`calibrate`);
- :mod:`.uncertainty`: standard errors, intervals, what is not identifiable;
- :mod:`.collisions`: the fitted model's first collision against the recorded ones;
- :mod:`.scene_out`: the calibrated scene and its ``calibration`` section;
- :mod:`.plot`: measured vs nominal vs fitted angles, and the residuals.
"""

from .data import Measured, read_measured
from .fit import CalibrationResult, calibrate
from .parameters import KINDS, PER, Parameters, parameters

__all__ = ["Measured", "read_measured", "CalibrationResult", "calibrate", "KINDS", "PER",
           "Parameters", "parameters"]

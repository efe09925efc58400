"""Free-vibration tests: hinge damping (and stiffness, and air drag) from recordings
of one panel swinging on one spring-loaded hinge, as the paper measured damping.

The rig is a scene of two bodies and one hinge (ground and panel; a 2 x 2
array merges into that). About the hinge axis it is one degree of freedom,

    I theta'' = -n k (theta - theta_e) - n c theta' + G(theta) - G(theta_e) - C_d D |theta'| theta'

with n springs of stiffness k (N m/rad) and damping c (N m s/rad) each, the
panel's inertia I (kg m^2), its gravity torque G (N m) and its air drag
torque per unit drag coefficient D (N m s^2), all three from the rig's model
(:func:`rig_of`). The equilibrium theta_e is measured, not computed: it takes
up the encoder's zero and the weight's preload, so k is identified by the
frequency alone. The joint stops are not in it: a swing that reaches one is
refused (:func:`check_swing`).

Each test is analysed two ways: the logarithmic decrement of its peaks
(:func:`log_decrement`) and a least-squares fit of the model's free response
(:func:`fit_swing`); :func:`pool` combines the tests by inverse-variance
weighting and says whether they agree. Failures to fit are results
(``success=False``), never exceptions; exceptions are for bad input.

Modules: :mod:`.rig` (the rig and its model), :mod:`.swing` (a recorded swing,
its extrema and checks), :mod:`.estimate` (the two analyses of one swing, and
pooling), :mod:`.report` (a calibration of several swings, its record and
report), :mod:`.synthetic` (swings made by the model); the package hands on
their main names.
"""

from __future__ import annotations

from .estimate import Analysis, Estimate, Pooled, fit_swing, log_decrement, pool
from .report import Calibration, calibrate, calibrated_scene, calibration_record, report_text
from .rig import Rig, rig_of
from .swing import Peaks, Swing, check_swing, find_peaks, read_swing
from .synthetic import record_swing, released

__all__ = ["Analysis", "Calibration", "Estimate", "Peaks", "Pooled", "Rig", "Swing", "calibrate",
           "calibrated_scene", "calibration_record", "check_swing", "find_peaks", "fit_swing",
           "log_decrement", "pool", "read_swing", "record_swing", "released", "report_text", "rig_of"]

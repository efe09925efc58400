"""Benchmarks of issue 3: work-precision against MuJoCo, and the stiff-case suite.

Library code for ``panel-deploy bench ...`` and the scripts in ``bench/``;
timings are printed and written, never asserted.
"""

from .work_precision import work_precision

__all__ = ["work_precision"]

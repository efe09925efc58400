"""Test-wide set-up: DDS traffic of every test that starts rclpy stays on this machine.

Done before rclpy is imported anywhere (conftest is imported first) and
inherited by the node processes the tests start; see ros_env.
"""

import subprocess
import sys
from pathlib import Path

import pytest

import ros_env

ros_env.isolate()


@pytest.fixture(scope="session")
def compiled_nodes():
    """Node processes import the *installed* package; from a checkout that is not
    the copy this test process imports, so its numba cache is filled separately.
    One short graph run through the installed command compiles every kernel the
    nodes use (dynamics, cut-hinge rates, collision monitor) before any test
    starts a node, so that no node test waits on a cold compile."""
    proc = subprocess.run([str(Path(sys.executable).parent / "panel-deploy"), "run", "paper_4x4",
                           "--real-time-factor", "0", "--set", "simulation.t_end=0.1"],
                          capture_output=True, text=True, timeout=1200)
    assert proc.returncode in (0, 1), proc.stderr

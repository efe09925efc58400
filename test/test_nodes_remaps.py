"""Node executables given remap arguments that are no ROS names: one line, exit 2
(as ``panel-deploy run --namespace``), never an RCLError traceback."""

import subprocess

import pytest
from ros_harness import executable


@pytest.mark.parametrize("rule, says", [
    ("__ns:=/ärray", "-r __ns:=/ärray: namespace must not contain characters other than"),
    ("__ns:=/" + "a" * 300, "namespace should not exceed"),
    ("__ns:=/a//b", "-r __ns:=/a//b: namespace must not contain repeated '/'"),
    ("__node:=ärray", "-r __node:=ärray: node name must not contain characters"),
    ("collision_monitor:__ns:=/x y", "namespace must not contain characters"),
])
def test_a_bad_remap_is_one_line(rule, says):
    proc = subprocess.run([executable("collision_monitor"), "--ros-args", "-r", rule],
                          capture_output=True, text=True, timeout=60)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert lines[0].startswith("panel-deploy: error: --ros-args: ") and says in lines[0]
    assert len(lines[0]) < 300

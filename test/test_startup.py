"""First-run behaviour: where numba caches the kernels, the one-line compile notice,
and that a run compiles only its own integrator."""

import os
import subprocess
import sys

from panel_deploy import _numba_cache


def _run(code, env_update, cwd):
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(env_update)
    return subprocess.run([sys.executable, "-c", code], env=env, cwd=cwd,
                          capture_output=True, text=True, timeout=300, check=True)


def test_cache_dir_choice(tmp_path, monkeypatch):
    env = {"XDG_CACHE_HOME": str(tmp_path / "xdg")}
    # writable package folder: numba's own choice (__pycache__ next to the sources)
    assert _numba_cache.chosen_cache_dir(tmp_path, env) is None
    # the user's NUMBA_CACHE_DIR wins, writable or not
    monkeypatch.setattr(_numba_cache.os, "access", lambda path, mode: False)
    assert _numba_cache.chosen_cache_dir(tmp_path, {**env, "NUMBA_CACHE_DIR": "/x"}) is None
    # read-only package folder: the per-user folder
    assert _numba_cache.chosen_cache_dir(tmp_path, env) == str(tmp_path / "xdg" / "panel_deploy"
                                                               / "numba")
    home = _numba_cache.user_cache_dir({})
    assert home == _numba_cache.Path.home() / ".cache" / "panel_deploy" / "numba"


# The package folder made read-only as far as the process can tell (the tests may
# run as root, who can write anywhere): the kernels must cache to the user folder.
READ_ONLY = """
import importlib.util, os, pathlib
real_access = os.access
# the package this process imports (the installed one, when the tests run from a checkout)
pkg = pathlib.Path(importlib.util.find_spec("panel_deploy").origin).parent
os.access = lambda p, m, **kw: False if pathlib.Path(p) == pkg else real_access(p, m, **kw)
import numba
from panel_deploy.dynamics import kernels
print(numba.config.CACHE_DIR)
print(kernels.hinge_law(4.0, 0.5, 0.1, 0.01, 1000.0, 0.5)[0])
"""


def test_read_only_package_caches_in_user_folder(tmp_path):
    code = READ_ONLY
    # not the working directory, whose panel_deploy/ would shadow the package
    xdg = {"XDG_CACHE_HOME": str(tmp_path / "xdg")}
    out = _run(code, xdg, tmp_path)
    target = tmp_path / "xdg" / "panel_deploy" / "numba"
    assert out.stdout.splitlines()[0] == str(target)
    assert any(p.name.startswith("kernels.hinge_law") for p in target.rglob("*.nbi"))
    again = _run(code, xdg, tmp_path)
    assert again.stdout == out.stdout
    assert _numba_cache.NOTICE not in again.stderr  # loaded from the user folder


NOTICE_RUN = """
from panel_deploy.dynamics import kernels
kernels.hinge_law(4.0, 0.5, 0.1, 0.01, 1000.0, 0.5)
kernels.contact_mode(1.0)
"""


def test_compile_notice_once_and_only_when_compiling(tmp_path):
    cold = _run(NOTICE_RUN, {"NUMBA_CACHE_DIR": str(tmp_path)}, tmp_path)
    assert cold.stderr.count(_numba_cache.NOTICE) == 1  # two kernels compiled, one line
    warm = _run(NOTICE_RUN, {"NUMBA_CACHE_DIR": str(tmp_path)}, tmp_path)
    assert _numba_cache.NOTICE not in warm.stderr


ONE_SCHEME = """
from panel_deploy.dynamics import integrate, rosenbrock, simulate
from panel_deploy.scene import SimulationSection
from test_dynamics_helpers import plate_on_hinge
model = plate_on_hinge()
simulate(model, SimulationSection(t_end=0.05, method="compiled", samples=3),
         compiled_scheme="dopri5")
print(len(integrate.COMPILED_LOOPS[integrate.DOPRI5].signatures),
      len(integrate.COMPILED_LOOPS[integrate.ROS34PW2].signatures),
      len(rosenbrock.step.signatures))
"""


def test_dopri5_run_does_not_compile_the_rosenbrock_loop(tmp_path):
    # the default cache (next to the sources), warm after the first test run
    test_dir = os.path.dirname(os.path.abspath(__file__))
    out = _run(ONE_SCHEME, {"PYTHONPATH": test_dir}, tmp_path)
    assert out.stdout.split() == ["1", "0", "0"]

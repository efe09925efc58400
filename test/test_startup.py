"""First-run behaviour: kernels compiled at install, where numba caches the others,
the one-line compile notice, and that a run compiles only its own integrator."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import panel_deploy
from panel_deploy import _numba_cache


def _run(code, env_update, cwd, locators=_numba_cache.NUMBA_LOCATORS):
    """``python -c code``; by default with numba's own locators, for the tests of
    what happens without kernels compiled at install."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("NUMBA_CACHE_DIR", "NUMBA_CACHE_LOCATOR_CLASSES")}
    if locators:
        env["NUMBA_CACHE_LOCATOR_CLASSES"] = locators
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
from panel_deploy.dynamics import hinges
print(numba.config.CACHE_DIR)
print(hinges.hinge_law(4.0, 0.5, 0.1, 0.01, 1000.0, 0.5, 0.0)[0])
"""


def test_read_only_package_caches_in_user_folder(tmp_path):
    code = READ_ONLY
    # not the working directory, whose panel_deploy/ would shadow the package
    xdg = {"XDG_CACHE_HOME": str(tmp_path / "xdg")}
    out = _run(code, xdg, tmp_path)
    target = tmp_path / "xdg" / "panel_deploy" / "numba"
    assert out.stdout.splitlines()[0] == str(target)
    assert any(p.name.startswith("hinges.hinge_law") for p in target.rglob("*.nbi"))
    again = _run(code, xdg, tmp_path)
    assert again.stdout == out.stdout
    assert _numba_cache.NOTICE not in again.stderr  # loaded from the user folder


NOTICE_RUN = """
from panel_deploy.dynamics import hinges
hinges.hinge_law(4.0, 0.5, 0.1, 0.01, 1000.0, 0.5, 0.0)
hinges.contact_mode(1.0)
"""


def test_compile_notice_once_and_only_when_compiling(tmp_path):
    cold = _run(NOTICE_RUN, {"NUMBA_CACHE_DIR": str(tmp_path)}, tmp_path)
    assert cold.stderr.count(_numba_cache.NOTICE) == 1  # two kernels compiled, one line
    warm = _run(NOTICE_RUN, {"NUMBA_CACHE_DIR": str(tmp_path)}, tmp_path)
    assert _numba_cache.NOTICE not in warm.stderr


ONE_SCHEME = """
from panel_deploy.dynamics import compiled, rosenbrock, simulate
from panel_deploy.scene import SimulationSection
from test_dynamics_helpers import plate_on_hinge
model = plate_on_hinge()
simulate(model, SimulationSection(t_end=0.05, method="dopri5", samples=3))
print(len(compiled.COMPILED_LOOPS[compiled.EXPLICIT].signatures),
      len(compiled.COMPILED_LOOPS[compiled.ROS34PW2].signatures),
      len(rosenbrock.step.signatures))
"""


def test_an_explicit_run_does_not_compile_the_rosenbrock_loop(tmp_path):
    # the package's own cache (next to the sources), warm after the first test run;
    # with numba's own locators this process would rewrite the installed package's
    # cache index with numba's stamp, and the package's next run would compile anew
    test_dir = os.path.dirname(os.path.abspath(__file__))
    out = _run(ONE_SCHEME, {"PYTHONPATH": test_dir}, tmp_path, locators=None)
    assert out.stdout.split() == ["1", "0", "0"]


TWO_KERNELS = """
import sys
from panel_deploy.dynamics import hinges
from panel_deploy import _numba_cache
hinges.hinge_law(4.0, 0.5, 0.1, 0.01, 1000.0, 0.5, 0.0)
if sys.argv[1:] == ["build"]:
    _numba_cache.COMPILED_MARKER.write_text("test")
else:
    hinges.contact_mode(1.0)
"""


def _package_copy(root):
    """The package's sources, without caches or marker, as a build starts from them."""
    source = Path(panel_deploy.__file__).parent
    shutil.copytree(source, root / "panel_deploy",
                    ignore=shutil.ignore_patterns("__pycache__", "_kernels_compiled"))
    return root / "panel_deploy"


def test_kernels_compiled_into_the_package_load_without_compiling(tmp_path):
    package = _package_copy(tmp_path / "site")
    env = {"PYTHONPATH": str(tmp_path / "site")}
    # the build: compiles hinge_law into the package's __pycache__, marks the package
    build = _run(TWO_KERNELS.replace("sys.argv[1:]", '["build"]'), env, tmp_path, locators=None)
    assert _numba_cache.NOTICE in build.stderr
    assert (package / "_kernels_compiled").exists()
    assert list((package / "dynamics" / "__pycache__").glob("hinges.hinge_law-*.nbi"))
    # a first run with a cache folder of the user's own: hinge_law comes from the
    # package, contact_mode (not compiled by the build) compiles into the package too
    user_cache = tmp_path / "user-cache"
    user_cache.mkdir()
    first = _run(TWO_KERNELS, {**env, "NUMBA_CACHE_DIR": str(user_cache)}, tmp_path, locators=None)
    assert first.stderr.count(_numba_cache.NOTICE) == 1
    assert list((package / "dynamics" / "__pycache__").glob("hinges.contact_mode-*.nbi"))
    assert not list(user_cache.rglob("*.nbi"))
    again = _run(TWO_KERNELS, {**env, "NUMBA_CACHE_DIR": str(user_cache)}, tmp_path, locators=None)
    assert _numba_cache.NOTICE not in again.stderr
    # without the marker the package's kernels are numba's business: the user's folder
    (package / "_kernels_compiled").unlink()
    unmarked = _run(TWO_KERNELS, {**env, "NUMBA_CACHE_DIR": str(user_cache)}, tmp_path,
                    locators=None)
    assert _numba_cache.NOTICE in unmarked.stderr
    assert list(user_cache.rglob("hinges.hinge_law-*.nbi"))


def _installed_package(cwd):
    """The folder of the package an installed ``panel-deploy`` imports."""
    out = subprocess.run([sys.executable, "-c", "import panel_deploy; print(panel_deploy.__file__)"],
                         cwd=cwd, capture_output=True, text=True, check=True)
    return Path(out.stdout.strip()).parent


def test_pip_installed_package_runs_paper_scene_without_compiling(tmp_path):
    installed = _installed_package(tmp_path)
    if installed == Path(__file__).resolve().parent.parent / "panel_deploy":
        pytest.skip("editable install: the kernels compile on first use (CI installs with pip)")
    assert (installed / "_kernels_compiled").exists(), "pip install did not compile the kernels"
    user_cache = tmp_path / "empty-cache"
    out = subprocess.run([sys.executable, "-m", "panel_deploy.cli", "simulate", "paper_4x4"],
                         cwd=tmp_path, capture_output=True, text=True, timeout=300,
                         env={**os.environ, "NUMBA_CACHE_DIR": str(user_cache)}, check=False)
    assert out.returncode == 0, out.stderr
    assert _numba_cache.NOTICE not in out.stderr
    assert not list(user_cache.rglob("*.nbi"))


def test_every_file_with_a_kernel_is_a_kernel_source():
    package = Path(panel_deploy.__file__).parent
    with_kernels = {str(p.relative_to(package)) for p in package.rglob("*.py")
                    if any(line.startswith("@njit") for line in p.read_text().splitlines())}
    assert with_kernels and with_kernels <= set(_numba_cache.KERNEL_SOURCES)


def test_the_kernel_stamp_follows_the_sources_contents_not_their_times(tmp_path):
    package = _package_copy(tmp_path)
    stamp = _numba_cache.kernel_sources_stamp(package)
    assert stamp == _numba_cache.kernel_sources_stamp(Path(panel_deploy.__file__).parent)
    os.utime(package / "dynamics" / "kernels.py", (1e9, 1e9))
    assert _numba_cache.kernel_sources_stamp(package) == stamp
    with open(package / "boxes.py", "a") as f:
        f.write("# an edit\n")
    assert _numba_cache.kernel_sources_stamp(package) != stamp


def test_the_packages_kernels_carry_the_kernel_stamp():
    from panel_deploy.dynamics import compiled, kernels
    for kernel in (kernels.rhs, compiled.COMPILED_LOOPS[compiled.EXPLICIT]):
        assert kernel._cache._cache_file._source_stamp == _numba_cache.kernel_sources_stamp()


# switches.first_switch calls hinges.contact_mode, in another file
SWITCH = """
import numpy as np
from panel_deploy.dynamics import switches
print(switches.first_switch(1, np.array([1.0, -2.0]), np.array([-1.0, -2.0]), 1.0, 1e-9))
"""


def test_a_kernel_recompiles_when_a_file_it_calls_into_changes(tmp_path):
    """numba stamps a cached kernel with its own file only: first_switch, cached
    before contact_mode (hinges.py) was edited, would keep the old one."""
    package = _package_copy(tmp_path / "site")
    env = {"PYTHONPATH": str(tmp_path / "site")}
    assert 0.0 < float(_run(SWITCH, env, tmp_path, locators=None).stdout) < 1.0  # theta crosses 0
    source = package / "dynamics" / "hinges.py"
    law = "return 0 if theta < 0.0 else (2 if theta > math.pi else 1)"
    assert law in source.read_text()
    source.write_text(source.read_text().replace(law, "return 1"))  # no limit any more
    assert float(_run(SWITCH, env, tmp_path, locators=None).stdout) == 2.0  # no switch

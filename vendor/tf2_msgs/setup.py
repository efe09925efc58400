"""Builds tf2_msgs (TFMessage) with CMake and packs what ``cmake --install`` gives
the way the ROS 2 Jazzy wheels on PyPI are packed: the Python package in
site-packages, the libraries, headers and ``share/`` (ament index, .msg/.idl) under
the environment's prefix, whose ``lib/`` the wheels' bootstrapper puts on
``LD_LIBRARY_PATH``.
"""

import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

from setuptools import Distribution, setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent
PACKAGE = "tf2_msgs"


def ros_prefixes():
    """Every prefix whose share/ holds ament_cmake: the (isolated) build environment's."""
    found = []
    for entry in [*sys.path, sysconfig.get_paths()["purelib"]]:
        prefix = Path(entry).parents[2] if Path(entry).name == "site-packages" else None
        if prefix and (prefix / "share" / "ament_cmake").is_dir() and prefix not in found:
            found.append(prefix)
    if not found:
        sys.exit("tf2_msgs: no ament_cmake found (pip installs it from pyproject.toml)")
    return found


class BuildInterfaces(build_py):
    """build_py, then configure, build (``-j1`` unless ``CMAKE_BUILD_PARALLEL_LEVEL``)
    and install the interface package into a staging folder, and take the wheel's
    contents from there."""

    def run(self):
        super().run()
        cmake = shutil.which("cmake")
        if cmake is None:
            sys.exit("tf2_msgs: cmake not found (it needs cmake, a C and C++ compiler and "
                     "Python's headers: apt-get install cmake g++ python3-dev)")
        temp = Path(self.get_finalized_command("build").build_temp).resolve()
        build, stage = temp / "cmake", temp / "stage"
        shutil.rmtree(build, ignore_errors=True)
        shutil.rmtree(stage, ignore_errors=True)
        prefixes = os.pathsep.join(map(str, ros_prefixes()))
        env = dict(os.environ, AMENT_PREFIX_PATH=prefixes, CMAKE_PREFIX_PATH=prefixes)
        jobs = os.environ.get("CMAKE_BUILD_PARALLEL_LEVEL", "1")
        for step in ([cmake, "-S", str(HERE), "-B", str(build), "-DCMAKE_BUILD_TYPE=Release",
                      f"-DCMAKE_INSTALL_PREFIX={stage}", f"-DPython3_EXECUTABLE={sys.executable}",
                      "-DBUILD_TESTING=OFF"],
                     [cmake, "--build", str(build), "-j", jobs],
                     [cmake, "--install", str(build)]):
            subprocess.run(step, check=True, env=env)
        site = stage / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}" / "site-packages"
        shutil.copytree(site / PACKAGE, Path(self.build_lib) / PACKAGE, dirs_exist_ok=True)
        data = {}
        for path in sorted(stage.rglob("*")):
            if path.is_file() and site not in path.parents:
                data.setdefault(str(path.parent.relative_to(stage)), []).append(str(path))
        self.distribution.data_files = sorted(data.items())


class BinaryDistribution(Distribution):
    def has_ext_modules(self):
        return True  # CPython extension modules: a wheel for this interpreter and platform


setup(
    name="panel-deploy-tf2-msgs",
    version="1.0.0",
    description="tf2_msgs/TFMessage (ROS 2 Jazzy) for rclpy from PyPI, built at install time",
    license="BSD-3-Clause",
    python_requires=">=3.11",
    install_requires=["ros-jazzy-geometry-msgs", "ros-jazzy-rosidl-default-runtime"],
    distclass=BinaryDistribution,
    cmdclass={"build_py": BuildInterfaces},
    zip_safe=False,
)

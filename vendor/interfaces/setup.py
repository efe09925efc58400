"""Builds the ROS interface packages that have no wheel on PyPI with CMake, and packs
what ``cmake --install`` gives the way the ROS 2 Jazzy wheels on PyPI are packed: the
Python packages in site-packages, the libraries, headers and ``share/`` (ament index,
.msg/.idl) under the environment's prefix, whose ``lib/`` the wheels' bootstrapper puts
on ``LD_LIBRARY_PATH``.

- ``tf2_msgs`` (TFMessage only), from ``tf2_msgs/`` here;
- ``panel_deploy_interfaces``, panel_deploy's messages and actions, whose package
  lives with the contract it belongs to (``panel_deploy/contract/interfaces``).
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
#: The interface packages built, by name: their CMake source folders.
PACKAGES = {"tf2_msgs": HERE / "tf2_msgs",
            "panel_deploy_interfaces": HERE.parents[1] / "panel_deploy" / "contract" / "interfaces"}


def ros_prefixes():
    """Every prefix whose share/ holds ament_cmake: the (isolated) build environment's."""
    found = []
    for entry in [*sys.path, sysconfig.get_paths()["purelib"]]:
        prefix = Path(entry).parents[2] if Path(entry).name == "site-packages" else None
        if prefix and (prefix / "share" / "ament_cmake").is_dir() and prefix not in found:
            found.append(prefix)
    if not found:
        sys.exit("interfaces: no ament_cmake found (pip installs it from pyproject.toml)")
    return found


class BuildInterfaces(build_py):
    """build_py, then configure, build (``-j1`` unless ``CMAKE_BUILD_PARALLEL_LEVEL``)
    and install each interface package into one staging folder, and take the wheel's
    contents from there."""

    def run(self):
        super().run()
        cmake = shutil.which("cmake")
        if cmake is None:
            sys.exit("interfaces: cmake not found (it needs cmake, a C and C++ compiler and "
                     "Python's headers: apt-get install cmake g++ python3-dev)")
        missing = [str(src) for src in PACKAGES.values() if not (src / "CMakeLists.txt").is_file()]
        if missing:  # pip builds a local folder in place: the repository must be whole
            sys.exit(f"interfaces: no CMakeLists.txt in {missing[0]} (install from a checkout "
                     "of the whole panel_deploy repository)")
        temp = Path(self.get_finalized_command("build").build_temp).resolve()
        stage = temp / "stage"
        shutil.rmtree(stage, ignore_errors=True)
        prefixes = os.pathsep.join(map(str, ros_prefixes()))
        env = dict(os.environ, AMENT_PREFIX_PATH=prefixes, CMAKE_PREFIX_PATH=prefixes)
        jobs = os.environ.get("CMAKE_BUILD_PARALLEL_LEVEL", "1")
        for package, source in PACKAGES.items():
            build = temp / "cmake" / package
            shutil.rmtree(build, ignore_errors=True)
            for step in ([cmake, "-S", str(source), "-B", str(build), "-DCMAKE_BUILD_TYPE=Release",
                          f"-DCMAKE_INSTALL_PREFIX={stage}", f"-DPython3_EXECUTABLE={sys.executable}",
                          f"-DCMAKE_PROJECT_INCLUDE={HERE / 'pypi_wheels.cmake'}",
                          "-DBUILD_TESTING=OFF"],
                         [cmake, "--build", str(build), "-j", jobs],
                         [cmake, "--install", str(build)]):
                subprocess.run(step, check=True, env=env)
        site = stage / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}" / "site-packages"
        for package in PACKAGES:
            shutil.copytree(site / package, Path(self.build_lib) / package, dirs_exist_ok=True)
        data = {}
        for path in sorted(stage.rglob("*")):
            if path.is_file() and site not in path.parents:
                data.setdefault(str(path.parent.relative_to(stage)), []).append(str(path))
        self.distribution.data_files = sorted(data.items())


class BinaryDistribution(Distribution):
    def has_ext_modules(self):
        return True  # CPython extension modules: a wheel for this interpreter and platform


setup(
    name="panel-deploy-interfaces",
    version="0.1.0",
    description="tf2_msgs/TFMessage and panel_deploy_interfaces (ROS 2 Jazzy) for rclpy from "
                "PyPI, built at install time",
    license="Apache-2.0 AND BSD-3-Clause",
    python_requires=">=3.11",
    install_requires=["ros-jazzy-geometry-msgs", "ros-jazzy-std-msgs", "ros-jazzy-action-msgs",
                      "ros-jazzy-rosidl-default-runtime"],
    distclass=BinaryDistribution,
    cmdclass={"build_py": BuildInterfaces},
    zip_safe=False,
)

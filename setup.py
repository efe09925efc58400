"""ament_python package that also installs with plain ``pip install .``."""

import os
import subprocess
import sys
from glob import glob

from setuptools import find_packages, setup
from setuptools.command.build_py import build_py

PACKAGE = "panel_deploy"
HERE = os.path.dirname(os.path.abspath(__file__))


class BuildWithKernels(build_py):
    """build_py, then compile the numba kernels into the package being built.

    The package's first run then loads them instead of compiling for minutes
    (see panel_deploy/_precompile.py). Where the build environment cannot run
    the package (colcon without numba, say), or PANEL_DEPLOY_COMPILE_KERNELS=0,
    the package is built without them and compiles on first use.
    """

    def run(self):
        super().run()
        if getattr(self, "editable_mode", False) or os.environ.get("PANEL_DEPLOY_COMPILE_KERNELS") == "0":
            return
        # a build folder left by an earlier build keeps that build's kernels: start clean
        for stale in glob(os.path.join(self.build_lib, PACKAGE, "**", "*.nb[ic]"), recursive=True):
            os.remove(stale)
        env = {k: v for k, v in os.environ.items()
               if k not in ("NUMBA_CACHE_DIR", "NUMBA_CACHE_LOCATOR_CLASSES")}
        # pip's isolated build environment is on PYTHONPATH too: keep it
        env["PYTHONPATH"] = os.pathsep.join(
            [os.path.abspath(self.build_lib)] + [p for p in [env.get("PYTHONPATH")] if p])
        env["PYTHONDONTWRITEBYTECODE"] = "1"
        print("compiling the numba kernels for this machine (a few minutes)", flush=True)
        done = subprocess.run(
            [sys.executable, "-m", f"{PACKAGE}._precompile",
             os.path.join(HERE, "config", "scenes", "paper_4x4.yaml")],
            cwd=self.build_lib, env=env, check=False, capture_output=True, text=True)
        if done.returncode != 0:
            why = (done.stderr.strip().splitlines() or ["no output"])[-1]
            print(f"kernels not compiled at install ({why}): they compile on first use",
                  flush=True)


setup(
    name=PACKAGE,
    version="0.1.0",
    description="Fold design, deployment dynamics, collision detection and stiffness "
                "optimisation of thick-panel arrays on spring-loaded hinges",
    license="Apache-2.0",
    python_requires=">=3.11",
    packages=find_packages(exclude=["test", "test.*", "bench"]),
    # The interface package's definitions: the core reads them (recordings' schemas).
    package_data={"panel_deploy.contract": ["interfaces/*.txt", "interfaces/*.xml",
                                            "interfaces/msg/*.msg", "interfaces/action/*.action"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml") + glob("config/*.xml")),
        (f"share/{PACKAGE}/config/scenes", glob("config/scenes/*.yaml")),
        (f"share/{PACKAGE}/launch", glob("launch/*.py")),
    ],
    install_requires=[
        "numpy>=1.26",
        "scipy>=1.11",
        "networkx>=3.0",
        "PyYAML>=6.0",
        "python-fcl>=0.7",
        "numba>=0.59",
        "matplotlib>=3.7",
        "tqdm>=4.60",
        "mcap>=1.6",
        "rosbags>=0.11",
        "rerun-sdk~=0.41.0",
    ],
    extras_require={
        "ros": ["ros-jazzy-rclpy[fastrtps]", "ros-jazzy-common-interfaces"],
        "test": ["pytest>=7", "mujoco>=3.0", "dask[distributed]>=2024.1", "yourdfpy>=0.0.56",
                 "mcap-ros2-support>=0.5", "hypothesis>=6.100", "pytest-xdist>=3.5"],
    },
    cmdclass={"build_py": BuildWithKernels},
    zip_safe=False,  # numba loads the compiled kernels from files next to the sources
    entry_points={
        "console_scripts": [
            "panel-deploy = panel_deploy.cli:main",
            "array_model = panel_deploy.nodes:array_model",
            "dynamics = panel_deploy.nodes:dynamics",
            "collision_monitor = panel_deploy.nodes:collision_monitor",
            "optimiser = panel_deploy.nodes:optimiser",
        ],
    },
)

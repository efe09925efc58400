"""ament_python package that also installs with plain ``pip install .``."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "panel_deploy"

setup(
    name=PACKAGE,
    version="0.1.0",
    description="Fold design, deployment dynamics, collision detection and stiffness "
                "optimisation of thick-panel arrays on spring-loaded hinges",
    license="Apache-2.0",
    python_requires=">=3.11",
    packages=find_packages(exclude=["test", "test.*", "bench"]),
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
                 "mcap-ros2-support>=0.5", "hypothesis>=6.100"],
    },
    zip_safe=True,
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

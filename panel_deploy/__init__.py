"""panel_deploy: fold design, deployment dynamics, collision detection and stiffness
optimisation of flat arrays of identical thick panels on spring-loaded hinges.

The core (this package minus :mod:`panel_deploy.nodes`) never imports rclpy.
Data flows one way: scene -> model -> simulation -> collision -> optimisation.
"""

from ._numba_cache import configure as _configure_numba_cache
from .errors import PanelDeployError

_configure_numba_cache()  # before any kernel module is imported

__version__ = "0.1.0"
__all__ = ["PanelDeployError", "__version__"]

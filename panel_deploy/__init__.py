"""panel_deploy: fold design, deployment dynamics, collision detection and stiffness
optimisation of flat arrays of identical thick panels on spring-loaded hinges.

The core (this package minus :mod:`panel_deploy.nodes`) never imports rclpy.
Data flows one way: scene -> model -> simulation -> collision -> optimisation.
"""

from .errors import PanelDeployError

__version__ = "0.1.0"
__all__ = ["PanelDeployError", "__version__"]

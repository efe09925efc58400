"""Recording deployments to MCAP (ROS 2 profile) and reading, replaying and checking recordings.

No rclpy here: messages are built and decoded with the ``rosbags`` ROS 2
Jazzy type store, files written by :mod:`.mcap_file` and read with the
``mcap`` library's record parsers.

Topics, QoS and the per-sample wire bytes are the contract's
(:mod:`panel_deploy.contract`, :mod:`panel_deploy.contract.cdr`).

- :mod:`.messages`: the other messages as rosbags messages, their CDR bytes and schemas.
- :mod:`.writer`: :class:`Recorder`, a ROS 2 recording laid out as rosbag2's MCAP
  storage writes it, on :mod:`.mcap_file` (chunks, indexes, summary), and
  :class:`~.writer.DeploymentWriter`, the one recording path of every command and node.
- :mod:`.deployment`: ``simulate --record`` and ``optimise --record``.
- :mod:`.reader`: :func:`open_recording`, :func:`joint_states`, :func:`hinge_track`.
- :mod:`.analysis`: the scene a recording ran, ``collide FILE.mcap`` (the monitor's
  check) and what ``replay`` needs from a recording.
- :mod:`.replay`: ``replay`` to rerun; :mod:`.strip`: ``replay --png``.
"""

from .reader import JointStates, Recording, hinge_track, is_mcap, joint_states, open_recording
from .writer import Recorder

__all__ = ["Recorder", "Recording", "JointStates", "open_recording", "joint_states",
           "hinge_track", "is_mcap"]

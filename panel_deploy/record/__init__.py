"""Recording deployments to MCAP (ROS 2 profile) and reading, replaying and checking recordings.

No rclpy here: messages are built and decoded with the ``rosbags`` ROS 2
Jazzy type store, files written by :mod:`.mcap_file` and read with the
``mcap`` library's record parsers.

- :mod:`.messages`: the topics, their types, and the messages built from core values.
- :mod:`.cdr`: the per-sample messages encoded fast, from precomputed layouts.
- :mod:`.writer`: :class:`Recorder`, a ROS 2 recording laid out as rosbag2's MCAP
  storage writes it, on :mod:`.mcap_file` (chunks, indexes, summary).
- :mod:`.deployment`: ``simulate --record`` and ``optimise --record``.
- :mod:`.reader`: :func:`open_recording`, :func:`joint_states`, :func:`hinge_track`.
- :mod:`.analysis`: ``collide FILE.mcap`` and what ``replay`` needs from a recording.
- :mod:`.replay`: ``replay`` to rerun; :mod:`.strip`: ``replay --png``.
"""

from .reader import JointStates, Recording, hinge_track, is_mcap, joint_states, open_recording
from .writer import Recorder

__all__ = ["Recorder", "Recording", "JointStates", "open_recording", "joint_states",
           "hinge_track", "is_mcap"]

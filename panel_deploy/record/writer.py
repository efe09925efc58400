"""Writing a ROS 2 recording to one MCAP file, laid out as rosbag2's MCAP storage does.

The file follows the MCAP ROS 2 profile: header profile ``ros2``; one schema
per message type (encoding ``ros2msg``, the Jazzy definition text); one
channel per topic (message encoding ``cdr``, channel metadata
``offered_qos_profiles`` and ``topic_type_hash`` as rosbag2 writes them);
messages in zstd-compressed chunks with message indexes; at the end chunk
indexes, statistics, summary offsets and the ``rosbag2`` metadata record
(``serialized_metadata``, rosbag2 metadata version 9), so that
``ros2 bag info FILE.mcap`` and ``ros2 bag play FILE.mcap`` (Jazzy: a single
storage file opens without a ``metadata.yaml``; rosbag2 takes counts and
durations from the MCAP statistics), Foxglove and rerun open it as it is.

Chunks close after :attr:`Recorder.chunk_span` seconds of log time (and at
:attr:`Recorder.chunk_bytes`) and are flushed to the operating system at
once (:mod:`.mcap_file` writes the records): a process killed at any moment
leaves every closed chunk readable, so at most ``chunk_span`` of log time
(plus the samples in flight) is lost.

The file is written as ``STEM.XXXXXXXX.part.mcap`` (random X) in the target's
folder and renamed to the target when closed: an existing recording is
replaced only by a whole one, two recorders of one target leave one whole
file (the last to finish), and a killed process leaves its recording under
the ``.part.mcap`` name (no summary: see README, recordings). If writing
fails (disk full, file size limit), the partial file is removed and the
target left as it was.
"""

from __future__ import annotations

import contextlib
import datetime
import json
import os
import shlex
import sys
from importlib.metadata import version
from pathlib import Path

import yaml

from .. import __version__, contract
from ..build import build_model
from ..contract.cdr import SampleEncoder
from ..errors import PanelDeployError, TrajectoryError
from ..kinematics import forward_kinematics
from ..scene_text import scene_from_yaml
from ..validate import in_place, output_target, temporary_beside
from . import messages
from .mcap_file import McapFile


#: rmw's "infinite" duration (``RMW_DURATION_INFINITE``) as rosbag2 stores it.
_INFINITE = {"sec": 9223372036, "nsec": 854775807}


def qos_profiles(qos: contract.QoS) -> list:
    """The ``offered_qos_profiles`` of one publisher (rosbag2 metadata version 9)."""
    return [{"history": "keep_last", "depth": qos.depth, "reliability": qos.reliability,
             "durability": qos.durability, "deadline": dict(_INFINITE),
             "lifespan": dict(_INFINITE), "liveliness": "automatic",
             "liveliness_lease_duration": dict(_INFINITE),
             "avoid_ros_namespace_conventions": False}]


def _qos_for(topic: str) -> list:
    """The contract's QoS of a resolved topic name (in any namespace); EVENTS for others."""
    found = contract.topic_of(topic)
    return qos_profiles(found[0].qos if found else contract.EVENTS)


#: libyaml's dumper when PyYAML has it (ten times faster), else the Python one.
_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


def _yaml(data) -> str:
    return yaml.dump(data, Dumper=_DUMPER, sort_keys=False)


class Recorder:
    """Writes messages to an MCAP file; use as a context manager or call :meth:`close`.

    Parameters
    ----------
    path : str or Path
        The ``.mcap`` file; an existing file is replaced when the recording
        is closed (written in place if ``path`` is a device or a pipe).
    chunk_span : float
        s of log time after which the open chunk is closed and flushed.
    chunk_bytes : int
        Uncompressed bytes after which the open chunk is closed anyway.

    Raises
    ------
    TrajectoryError
        The file cannot be created, or (from any method) written.
    """

    def __init__(self, path, *, chunk_span: float = 0.25, chunk_bytes: int = 4 << 20):
        self.path = output_target(path)
        self.chunk_span = chunk_span
        self.chunk_bytes = chunk_bytes
        #: Where the recording is written until :meth:`close` renames it to
        #: :attr:`path` (None: written in place).
        self.partial = None
        self.closed = False
        with self._writing():
            if in_place(self.path):
                self._stream = open(self.path, "wb")
            else:
                fd, self.partial = temporary_beside(self.path, f"{self.path.stem}.",
                                                    f".part{self.path.suffix}")
                self._stream = os.fdopen(fd, "wb")
            self._file = McapFile(self._stream, "ros2", f"panel_deploy {__version__}")
        self._schemas: dict = {}    # type name -> schema id
        self._channels: dict = {}   # topic -> (channel id, type name)
        self._counts: dict = {}     # topic -> messages
        self._chunk_start = None    # log time (ns) of the open chunk's first message
        self.first_time = self.last_time = None

    @contextlib.contextmanager
    def _writing(self):
        """File errors as one TrajectoryError, the partial file removed: a
        recording that cannot be written whole is not left half written."""
        try:
            yield
        except OSError as e:
            self.closed = True
            with contextlib.suppress(OSError, AttributeError):
                self._stream.close()
            if self.partial is not None:
                with contextlib.suppress(OSError):
                    os.unlink(self.partial)
            kept = (f"; {self.path} is unchanged" if self.partial is not None and self.path.exists()
                    else "")
            raise TrajectoryError(f"{self.path}: cannot write the recording "
                                  f"({e.strerror or e}){kept}") from None

    def channel(self, topic: str, typename: str) -> int:
        """The channel id of ``topic`` (registered on first use with ``typename``).

        Raises
        ------
        TrajectoryError
            ``topic`` was registered with another type.
        """
        if topic in self._channels:
            cid, known = self._channels[topic]
            if known != typename:
                raise TrajectoryError(f"{self.path}: {topic} is {known}, cannot also record {typename}")
            return cid
        with self._writing():
            if typename not in self._schemas:
                self._schemas[typename] = len(self._schemas) + 1
                self._file.schema(self._schemas[typename], typename, "ros2msg",
                                  messages.msgdef(typename).encode())
            cid = len(self._channels) + 1
            self._file.channel(cid, self._schemas[typename], topic, "cdr",
                               {"offered_qos_profiles": _yaml(_qos_for(topic)),
                                "topic_type_hash": messages.type_hash(typename)})
        self._channels[topic] = (cid, typename)
        self._counts[topic] = 0
        return cid

    def write(self, topic: str, typename: str, message, log_time: int) -> None:
        """Record one message.

        Parameters
        ----------
        topic, typename : str
            e.g. ``"/joint_states"``, ``"sensor_msgs/msg/JointState"``.
        message : rosbags message or bytes
            A message of the rosbags Jazzy type store, or its CDR bytes,
            stored as given. Bytes from rclpy (a subscription with
            ``raw=True``, ``serialize_message``) may end in stray padding
            that rosbags' strict decoder rejects: pass them through
            :func:`.messages.trim` first.
        log_time : int
            ns; simulated time for a deployment.
        """
        cid = self.channel(topic, typename)
        data = message if isinstance(message, bytes) else (
            bytes(message) if isinstance(message, (bytearray, memoryview)) else
            messages.serialize(message))
        if self._chunk_start is not None and (log_time - self._chunk_start >= self.chunk_span * 1e9
                                              or self._file.chunk_bytes >= self.chunk_bytes):
            self.flush()
        if self._chunk_start is None:
            self._chunk_start = log_time
        self._file.message(cid, log_time, data)
        self._counts[topic] += 1
        if self.first_time is None:
            self.first_time = self.last_time = log_time
        else:
            self.first_time = min(self.first_time, log_time)
            self.last_time = max(self.last_time, log_time)

    def flush(self) -> None:
        """Close the open chunk and hand everything written to the operating system."""
        with self._writing():
            self._file.close_chunk()
        self._chunk_start = None

    def metadata(self, name: str, values: dict) -> None:
        """An MCAP metadata record: ``values`` become strings (JSON, which is
        also YAML, for anything but a string). Written at once, between chunks."""
        with self._writing():
            self._file.metadata(name, {str(k): v if isinstance(v, str) else json.dumps(v)
                                       for k, v in values.items()})

    def bag_metadata(self) -> dict:
        """rosbag2's ``BagMetadata`` (version 9) of what has been written."""
        start = self.first_time or 0
        duration = 0 if self.first_time is None else self.last_time - self.first_time
        total = sum(self._counts.values())
        return {
            "version": 9, "storage_identifier": "mcap",
            "duration": {"nanoseconds": duration},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": total,
            "topics_with_message_count": [
                {"topic_metadata": {"name": topic, "type": typename, "serialization_format": "cdr",
                                    "offered_qos_profiles": _qos_for(topic),
                                    "type_description_hash": messages.type_hash(typename)},
                 "message_count": self._counts[topic]}
                for topic, (_, typename) in self._channels.items()],
            "compression_format": "", "compression_mode": "",
            "relative_file_paths": [self.path.name],
            "files": [{"path": self.path.name,
                       "starting_time": {"nanoseconds_since_epoch": start},
                       "duration": {"nanoseconds": duration}, "message_count": total}],
            "custom_data": {}, "ros_distro": "jazzy",
        }

    def close(self) -> None:
        """Write the summary (indexes, statistics) and the rosbag2 metadata record;
        close the file and rename it to :attr:`path`."""
        if self.closed:
            return
        self.flush()
        self.metadata("rosbag2", {"serialized_metadata": _yaml(self.bag_metadata())})
        with self._writing():
            self._file.finish()
            self._stream.close()
            if self.partial is not None:
                os.replace(self.partial, self.path)
        self.closed = True

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def run_metadata() -> dict:
    """The ``run`` metadata record: package and library versions, wall-clock
    start (UTC, ISO 8601), Python and the process's command-line arguments."""
    return {"package": "panel_deploy", "version": __version__,
            "wall_time": datetime.datetime.now(datetime.timezone.utc).isoformat(),
            "python": sys.version.split()[0], "mcap": version("mcap"),
            "rosbags": version("rosbags"), "arguments": shlex.join(sys.argv[1:])}


def _relative(source) -> str:
    """A scene file relative to the working directory when it lies below it."""
    if not source:
        return ""
    path = Path(source).resolve()
    return str(path.relative_to(Path.cwd())) if path.is_relative_to(Path.cwd()) else str(source)


def model_record(model) -> dict:
    """The ``model`` metadata record: k and c of one spring per hinge (model
    order), springs per hinge, joint-stop contact, closure, gravity, air and
    panel contact."""
    c = model.closure
    return {"hinges": [h.name for h in model.hinges],
            "stiffness": [float(h.k) for h in model.hinges],           # N m/rad, one spring
            "damping": [float(h.c) for h in model.hinges],             # N m s/rad, one spring
            "springs": [int(h.springs) for h in model.hinges],
            "k_s": float(model.k_s), "c_s": float(model.c_s), "stop_ramp": float(model.stop_ramp),
            "closure": c.method, "k_M": c.k_M, "c_M": c.c_M, "k_N": c.k_N, "c_N": c.c_N,
            "gravity": [float(g) for g in model.gravity],
            "air_density": model.air.density, "drag_coefficient": model.air.drag_coefficient,
            "panel_contacts": len(model.contact_pairs), "k_p": model.k_p, "c_p": model.c_p,
            "contact_pressure": model.contact_pressure,
            "friction": model.mu_p, "friction_speed": model.friction_speed}


def integrator_record(scene) -> dict:
    """The ``integrator`` metadata record of a scene's simulation and collision settings."""
    s = scene.simulation
    return {"method": s.method, "rtol": s.rtol, "atol": s.atol, "t_end": s.t_end,
            "samples": s.samples, "rate_hz": (s.samples - 1) / s.t_end,
            "flat_tolerance": s.flat_tolerance, "collision_tolerance": scene.collision.tolerance}


def outcome_record(summary: dict) -> dict:
    """The ``outcome`` metadata record of a :func:`deployment_summary` with its
    collision part: success, time to flat (s), first collision (t s, pair,
    approach speed v m/s) and the smallest distance d (m)."""
    c = summary["collision"]
    first = c["first_collision"]
    return {"success": bool(summary["success"]), "message": summary["message"],
            "t_end": summary["t_end"], "time_to_flat": summary["time_to_flat"],
            "collided": c["collided"],
            "first_collision_t": None if first is None else float(first["t"]),
            "first_collision_pair": None if first is None else list(first["pair"]),
            "approach_speed": float(c["v"]) if first is not None else None,
            "d": None if c["d"] is None else float(c["d"]), "wall_time": summary["wall_time"]}


def _stamp_ns(message) -> int | None:
    """The simulated-time stamp of a contract message, ns (None without one)."""
    if hasattr(message, "header"):
        stamp = message.header.stamp
    elif message.__msgtype__ == contract.CLOCK:
        stamp = message.clock
    elif getattr(message, "markers", None):
        stamp = message.markers[0].header.stamp
    elif getattr(message, "transforms", None):
        stamp = message.transforms[0].header.stamp
    else:
        return None
    return stamp.sec * 1_000_000_000 + stamp.nanosec


class DeploymentWriter:
    """The recording of one deployment graph, the one path of every recording:
    ``simulate --record`` hands it what it computes, the recorder node of
    ``run --record`` what it receives; both make the same file.

    Every topic of :mod:`panel_deploy.contract` gets a channel (resolved in
    ``namespace``, so a namespaced graph keeps its names), even one left
    empty. The log time of a stamped topic's message is its stamp (simulated
    time); any other message is logged at the latest stamp written before it
    (0 before the deployment starts). :meth:`deployed` records what runs:
    the ``scene`` (the effective scene: k and c per hinge and every override),
    ``model`` and ``integrator`` metadata and ``/tf_static``; :meth:`close`
    the ``outcome`` record and the file's summary.

    Raises
    ------
    TrajectoryError
        The file cannot be created or written.
    """

    def __init__(self, path, namespace: str = ""):
        self.file = Recorder(path)
        self.namespace = namespace
        self.now = 0  # ns: the latest stamp written
        self.model = None
        self.file.metadata("run", {**run_metadata(), "namespace": namespace})
        for topic in contract.TOPICS:
            self.file.channel(self.name(topic), topic.type)

    @property
    def closed(self) -> bool:
        return self.file.closed

    def name(self, topic: contract.Topic) -> str:
        """``topic`` resolved in this recording's namespace."""
        return contract.resolve(topic.name, self.namespace)

    def write(self, topic: contract.Topic, message, stamp: int | None = None) -> None:
        """Record ``message`` (a rosbags message or its CDR bytes) on ``topic``.

        ``stamp`` (ns) saves decoding a stamped message's bytes to find its
        stamp; rclpy's stray padding is trimmed from bytes (see
        :func:`.messages.trim`).
        """
        if isinstance(message, (bytes, bytearray, memoryview)):
            data = messages.trim(message, topic.type)
            if topic.stamped and stamp is None:
                stamp = _stamp_ns(messages.deserialize(data, topic.type))
        else:
            data = messages.serialize(message)
            if topic.stamped and stamp is None:
                stamp = _stamp_ns(message)
        if topic.stamped and stamp is not None:
            self.now = max(self.now, stamp)
        self.file.write(self.name(topic), topic.type, data,
                        stamp if topic.stamped and stamp is not None else self.now)

    def deployed(self, scene, model, text: str, source: str = "") -> None:
        """What the deployment runs: its scene text (``text``, the effective
        scene) on ``dynamics/scene`` and as the ``scene`` metadata, ``model``
        and ``integrator`` metadata, and ``/tf_static``."""
        self.model = model
        self.file.metadata("scene", {"name": scene.name or "", "source": _relative(source),
                                     "yaml": text})
        self.file.metadata("model", model_record(model))
        self.file.metadata("integrator", integrator_record(scene))
        self.write(contract.DEPLOYED_SCENE, messages.string(text))
        self._encoder = SampleEncoder(model)
        self.write(contract.TF_STATIC, self._encoder.tf_static())

    def receive(self, topic: contract.Topic, data) -> None:
        """Record CDR bytes received on ``topic`` from a live graph.

        The deployed scene (``dynamics/scene``) is recorded by :meth:`deployed`
        (a scene that does not load is recorded as it came, with a
        PanelDeployError); each joint state of the deployed model's hinges
        adds its ``/tf``, as robot_state_publisher would send it.
        """
        if topic is contract.DEPLOYED_SCENE:
            text = messages.deserialize(data, topic.type).data
            try:
                scene = scene_from_yaml(text, source=self.name(topic))
                model = build_model(scene)
            except PanelDeployError:
                self.write(topic, data)
                raise
            self.deployed(scene, model, text, scene.source)
        elif topic is contract.JOINT_STATES:
            message = messages.deserialize(data, topic.type)
            stamp = _stamp_ns(message)
            self.write(topic, data, stamp)
            self._tf(message, stamp)
        else:
            self.write(topic, data)

    def _tf(self, joint_state, stamp: int) -> None:
        model = self.model
        if model is None:
            return
        index = {name: i for i, name in enumerate(joint_state.name)}
        try:
            theta = [joint_state.position[index[model.hinges[h].name]] for h in model.joints]
        except KeyError:
            return  # not this model's joint states: recorded, but no /tf for them
        R, p = forward_kinematics(model, theta)[:2]
        self.write(contract.TF, self._encoder.tf(R, p, stamp * 1e-9), stamp)

    def close(self, summary: dict | None = None) -> None:
        """Write the ``outcome`` record of a deployment summary (if given) and
        the file's summary, and rename the file into place."""
        if self.file.closed:
            return
        if summary is not None:
            self.file.metadata("outcome", outcome_record(summary))
        self.file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

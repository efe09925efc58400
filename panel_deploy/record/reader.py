"""Reading a ROS 2 MCAP recording back: ours, or any ``ros2 bag record`` of ``/joint_states``.

:func:`open_recording` reads the file's records in order (chunk CRCs
checked) without needing its summary, so a recording cut short (a process
killed mid-run) is read up to its last complete record and flagged
:attr:`Recording.truncated`. :func:`joint_states` gives the ``/joint_states``
stream as arrays and :func:`hinge_track` maps it onto a model's hinges.
Every problem is a :class:`~panel_deploy.errors.TrajectoryError` whose
one-line message starts with the file name.
"""

from __future__ import annotations

import mmap
import struct
from dataclasses import dataclass, field, replace
from io import BytesIO
from pathlib import Path

import numpy as np
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Header, Message, Metadata, Schema
from mcap.stream_reader import breakup_chunk

from ..errors import PanelDeployError, TrajectoryError, shown
from ..validate import foreign_file
from .. import contract
from ..model import hinge_order
from . import messages

MAGIC = b"\x89MCAP0\r\n"
#: Uncompressed chunk size read whatever its compression ratio. Writers close
#: chunks at a few MiB (this package at 4 MiB, rosbag2 at 768 KiB), but one
#: large message (a camera image) makes a larger chunk.
MAX_CHUNK_BYTES = 32 << 20
#: Above :data:`MAX_CHUNK_BYTES`, a chunk may inflate to at most this many
#: times its compressed size: a chunk is inflated whole and split record by
#: record in Python, and a 1 GiB chunk of zeros (30 kB compressed, 35,000 to
#: 1) would take gigabytes and minutes, while sensor data compress 2-10 fold.
MAX_CHUNK_RATIO = 64
#: The chunk compressions of the MCAP specification.
COMPRESSIONS = ("", "zstd", "lz4")


def is_mcap(path) -> bool:
    """True when ``path`` names an MCAP file (by suffix or by its leading magic bytes)."""
    path = Path(path)
    if path.suffix == ".mcap":
        return True
    try:
        with open(path, "rb") as f:
            return f.read(len(MAGIC)) == MAGIC
    except OSError:
        return False


@dataclass
class Recording:
    """What an MCAP file holds, read in file order.

    Attributes
    ----------
    path : Path
    profile, library : str
        From the MCAP header (``ros2`` for a ROS 2 recording).
    topics : dict
        topic -> message type name (the channel's schema name).
    encodings : dict
        topic -> message encoding (``cdr`` for ROS 2).
    metadata : dict
        Metadata record name -> {key: value} (str).
    truncated : str or None
        Why the file ends early (then it was read up to its last complete
        record); None for a complete file.
    namespace : str
        The graph namespace whose topics :meth:`topic` names ("" for the
        root): see :func:`open_recording`.
    """

    path: Path
    profile: str = ""
    library: str = ""
    topics: dict = field(default_factory=dict)
    encodings: dict = field(default_factory=dict)
    metadata: dict = field(default_factory=dict)
    truncated: str | None = None
    namespace: str = ""
    _raw: dict = field(default_factory=dict, repr=False)   # topic -> [(log_time ns, bytes)]

    def topic(self, topic: contract.Topic) -> str:
        """The name of a contract topic in this recording's namespace."""
        return contract.resolve(topic.name, self.namespace)

    def namespaces(self) -> list:
        """Every namespace whose ``joint_states`` this file holds, sorted."""
        found = (contract.namespace_of(name, contract.JOINT_STATES) for name in self.topics)
        return sorted({ns for ns in found if ns is not None})

    def count(self, topic: str) -> int:
        """Messages read on ``topic``."""
        return len(self._raw.get(topic, ()))

    def messages(self, topic: str, typename: str | None = None) -> list:
        """``[(log_time ns, message)]`` of ``topic`` in log-time order (exact repeats
        once), decoded with the rosbags Jazzy type store.

        Raises
        ------
        TrajectoryError
            ``topic`` is absent, of another type than ``typename``, not CDR,
            or a message does not decode.
        """
        if topic not in self.topics:
            raise TrajectoryError(f"{self.path}: no {topic} in this recording (topics: "
                                  f"{', '.join(sorted(self.topics)) or 'none'})")
        actual = self.topics[topic]
        if typename is not None and actual != typename:
            raise TrajectoryError(f"{self.path}: {topic} is {actual or 'of no type'}, "
                                  f"expected {typename}")
        if self.encodings[topic] != "cdr":
            raise TrajectoryError(f"{self.path}: {topic} is encoded as "
                                  f"{shown(self.encodings[topic])}, expected ROS 2 'cdr'")
        out, previous = [], None
        # In log-time order (a file's order may differ; MCAP readers sort), an
        # exact repeat of a message (same time, same bytes) read once.
        for i, (log_time, data) in enumerate(sorted(self._raw.get(topic, ()), key=lambda r: r[0])):
            if (log_time, bytes(data)) == previous:
                continue
            previous = (log_time, bytes(data))
            try:
                out.append((log_time, messages.deserialize(data, actual)))
            except ValueError as e:
                raise TrajectoryError(f"{self.path}: {topic} message {i} does not decode ({e})") from None
        return out

    def scene(self):
        """The scene the recorded deployment ran: the last ``dynamics/scene``
        (the effective scene, overrides included), else the last
        ``panel_deploy/model``; None without either.

        Raises
        ------
        TrajectoryError
            The scene text is not a valid scene.
        """
        from ..scene_text import scene_from_yaml

        for topic in (contract.DEPLOYED_SCENE, contract.MODEL):
            name = self.topic(topic)
            if self.count(name):
                text = self.messages(name, topic.type)[-1][1].data
                try:
                    return scene_from_yaml(text, source=f"{self.path}:{name}")
                except PanelDeployError as e:
                    raise TrajectoryError(f"{self.path}: {name} is not a valid scene ({e})") from None
        return None


def open_recording(path, namespace: str | None = None) -> Recording:
    """Read an MCAP file's records (messages kept as bytes, decoded on demand).

    ``namespace`` chooses the graph whose topics the recording's readers take
    (``array7`` or ``/array7``: ``/array7/joint_states``); None takes the one
    graph whose ``joint_states`` the file holds (the root when there is none).

    Raises
    ------
    TrajectoryError
        Missing, empty, not MCAP, corrupt (a record that does not parse, a
        chunk whose CRC or compression fails), nothing recorded, joint states
        of several graphs and no ``namespace``, or a ``namespace`` the file
        has no joint states of.
    """
    path = Path(path)
    foreign = foreign_file(path)
    if foreign:
        raise TrajectoryError(f"{path}: {foreign}")
    try:
        f = open(path, "rb")
    except OSError as e:
        raise TrajectoryError(f"{path}: cannot read the recording ({e.strerror})") from None
    with f:
        size = Path(path).stat().st_size
        if size == 0:
            raise TrajectoryError(f"{path}: empty file, not an MCAP recording")
        with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as data:
            if data[:len(MAGIC)] != MAGIC:
                raise TrajectoryError(f"{path}: not an MCAP file (it does not start with the "
                                      f"MCAP magic bytes)")
            recording = Recording(path)
            _read_records(recording, data, size)
    if not recording._raw:
        why = f" ({recording.truncated})" if recording.truncated else ""
        raise TrajectoryError(f"{path}: no messages in this recording{why}")
    recording.namespace = _namespace(recording, namespace)
    return recording


def _namespace(recording: Recording, namespace: str | None) -> str:
    found = recording.namespaces()
    if namespace is not None:
        wanted = "/" + namespace.strip("/") if namespace.strip("/") else ""
        if found and wanted not in found:
            raise TrajectoryError(f"{recording.path}: no joint states in namespace "
                                  f"{shown(wanted or '/')} (this file has them in "
                                  f"{', '.join(ns or '/' for ns in found)})")
        return wanted
    if len(found) > 1:
        raise TrajectoryError(f"{recording.path}: joint states of several arrays "
                              f"({', '.join(ns or '/' for ns in found)}): choose one with "
                              f"--namespace")
    return found[0] if found else ""


def _read_records(recording: Recording, data, size: int) -> None:
    schemas, channels = {}, {}
    pos = len(MAGIC)
    while True:
        if pos + 9 > size:
            recording.truncated = f"ends at byte {size} without the MCAP footer"
            return
        opcode, length = struct.unpack_from("<BQ", data, pos)
        end = pos + 9 + length
        if end > size:
            recording.truncated = (f"cut at byte {size} inside a record of {length} bytes "
                                   f"that starts at byte {pos}")
            return
        try:
            records = _parse(opcode, data[pos + 9:end], length)
        except Exception as e:  # struct, CRC, decompression, UTF-8: all mean corrupt
            name = Opcode(opcode).name if opcode in Opcode._value2member_map_ else f"opcode {opcode}"
            raise TrajectoryError(f"{recording.path}: corrupt {name.lower()} record at byte {pos} "
                                  f"({e})") from None
        for r in records:
            if isinstance(r, Header):
                recording.profile, recording.library = r.profile, r.library
            elif isinstance(r, Schema):
                schemas[r.id] = r
            elif isinstance(r, Channel):
                channels[r.id] = r
                schema = schemas.get(r.schema_id)
                recording.topics[r.topic] = schema.name if schema else ""
                recording.encodings[r.topic] = r.message_encoding
                recording._raw.setdefault(r.topic, [])
            elif isinstance(r, Message):
                channel = channels.get(r.channel_id)
                if channel is None:
                    raise TrajectoryError(f"{recording.path}: corrupt: a message at byte {pos} "
                                          f"names channel {r.channel_id}, never defined")
                recording._raw[channel.topic].append((r.log_time, r.data))
            elif isinstance(r, Metadata):
                recording.metadata[r.name] = dict(r.metadata)
        if opcode == Opcode.FOOTER:
            return
        pos = end


def _parse(opcode: int, body, length: int) -> list:
    stream = ReadDataStream(BytesIO(body))
    if opcode == Opcode.CHUNK:
        return breakup_chunk(_bounded(Chunk.read(stream)), validate_crc=True)
    if opcode == Opcode.MESSAGE:
        return [Message.read(stream, length)]
    for record in (Header, Schema, Channel, Metadata):
        if opcode == getattr(Opcode, record.__name__.upper()):
            return [record.read(stream)]
    return []  # indexes, statistics, summary records, attachments: not needed here


def _bounded(chunk: Chunk) -> Chunk:
    """``chunk`` with its data decompressed, refused if it declares or holds
    more than :data:`MAX_CHUNK_BYTES` (the compressed frame's own size field is
    not trusted either: never more than the declared size is inflated). The
    caller names the file and the record's position."""
    if chunk.compression not in COMPRESSIONS:
        raise TrajectoryError(f"its compression {shown(chunk.compression)} is none of the MCAP "
                              f"specification's (zstd, lz4, or none)")
    limit = max(MAX_CHUNK_BYTES, MAX_CHUNK_RATIO * len(chunk.data))
    if chunk.compression and chunk.uncompressed_size > limit:
        raise TrajectoryError(f"it declares {chunk.uncompressed_size} bytes uncompressed from "
                              f"{len(chunk.data)} compressed, above the reader's limit of {limit} "
                              f"({MAX_CHUNK_RATIO} to 1 above {MAX_CHUNK_BYTES} bytes)")
    if chunk.compression == "zstd":
        with zstandard.ZstdDecompressor().stream_reader(chunk.data) as stream:
            data = stream.read(chunk.uncompressed_size + 1)
    elif chunk.compression == "lz4":
        try:
            import lz4.frame
        except ImportError:  # mcap's optional codec: breakup_chunk reports it missing
            return chunk
        data = lz4.frame.LZ4FrameDecompressor().decompress(chunk.data,
                                                          max_length=chunk.uncompressed_size + 1)
    else:
        return chunk
    if len(data) != chunk.uncompressed_size:
        held = "more" if len(data) > chunk.uncompressed_size else len(data)
        raise TrajectoryError(f"it declares {chunk.uncompressed_size} bytes uncompressed but "
                              f"holds {held}")
    return replace(chunk, compression="", data=data)


@dataclass
class JointStates:
    """The ``/joint_states`` stream as arrays, joints in the first message's order.

    Attributes
    ----------
    t : (s,) ndarray
        ``header.stamp`` of every message, s.
    names : list of str
    position : (s, n) ndarray
        rad.
    velocity, effort : (s, n) ndarray or None
        rad/s and N m; None when the messages carry none (effort: or one not finite).
    log_time : (s,) ndarray
        When each message was recorded (the MCAP log time), s: its arrival
        for ``ros2 bag record``, its stamp for this package's recordings.
    """

    t: np.ndarray
    names: list
    position: np.ndarray
    velocity: np.ndarray | None
    effort: np.ndarray | None
    log_time: np.ndarray | None = None


def joint_states(recording: Recording, stamps: str = "header") -> JointStates:
    """The ``/joint_states`` of a recording, checked message by message.

    ``stamps`` "header" times each by its ``header.stamp``; "receipt" by its
    log time (when ``ros2 bag record`` received it: for drivers that leave
    stamps unfilled), the header stamps then unread.

    Raises
    ------
    TrajectoryError
        No such topic or messages; a message whose names differ from the
        first one's, whose arrays do not match its names, with values that
        are not finite, or whose stamp is not after the previous one's.
    """
    path = recording.path
    topic = recording.topic(contract.JOINT_STATES)
    logged = recording.messages(topic, contract.JOINT_STATE)
    msgs = [msg for _, msg in logged]
    if not msgs:
        raise TrajectoryError(f"{path}: {topic} has no messages")
    names = list(msgs[0].name)
    n, s = len(names), len(msgs)
    if n == 0 or len(set(names)) != n:
        raise TrajectoryError(f"{path}: {topic} message 0 names "
                              f"{'no joint' if n == 0 else 'a joint twice'}")
    t = np.empty(s)
    arrays = {"position": np.empty((s, n)), "velocity": np.empty((s, n)), "effort": np.empty((s, n))}
    present = {key: len(getattr(msgs[0], key)) == n for key in arrays}
    if not present["position"]:
        raise TrajectoryError(f"{path}: {topic} message 0 has {len(msgs[0].position)} "
                              f"positions for {n} names")
    for j, msg in enumerate(msgs):
        where = f"{path}: {topic} message {j}"
        order = list(range(n)) if list(msg.name) == names else _order(msg.name, names, where)
        for key, out in arrays.items():
            values = getattr(msg, key)
            if present[key]:
                if len(values) != n:
                    raise TrajectoryError(f"{where}: {len(values)} {key} values for {n} names")
                out[j] = np.asarray(values, dtype=float)[order]
        t[j] = (messages.seconds(msg.header.stamp) if stamps == "header"
                else logged[j][0] * 1e-9)
        if j and not t[j] > t[j - 1]:
            raise TrajectoryError(f"{where}: stamp {t[j]:.9g} s is not after the previous "
                                  f"one ({t[j - 1]:.9g} s)")
    # Efforts are carried along, never used: one that is not finite only drops them.
    if present["effort"] and not np.all(np.isfinite(arrays["effort"])):
        present["effort"] = False
    for key, out in arrays.items():
        if present[key] and not np.all(np.isfinite(out)):
            j, i = (int(x) for x in np.argwhere(~np.isfinite(out))[0])
            raise TrajectoryError(f"{path}: {topic} message {j}: {key} of {names[i]} is "
                                  f"{out[j, i]} (not finite)")
    return JointStates(t, names, arrays["position"],
                       arrays["velocity"] if present["velocity"] else None,
                       arrays["effort"] if present["effort"] else None,
                       np.array([log_time for log_time, _ in logged], dtype=float) * 1e-9)


def contact_onsets(recording: Recording, states: JointStates, stamps: str = "header") -> list:
    """The contact onset the recording's ``dynamics/contact_onsets`` gives for
    each joint state of ``states`` (matched by its time: header stamp, or log
    time with ``stamps`` "receipt"), as the fields
    :meth:`~panel_deploy.collision.StreamCheck.onset` takes; None for a joint
    state with none (a recording of a model without panel contact, or of a
    real array, has none at all).

    Raises
    ------
    TrajectoryError
        The topic holds messages that do not decode as ``ContactOnset``.
    """
    topic = recording.topic(contract.CONTACT_ONSETS)
    if not recording.count(topic):
        return [None] * len(states.t)
    by_time = {(messages.seconds(msg.header.stamp) if stamps == "header" else log_time * 1e-9):
               contract.onset_fields(msg)
               for log_time, msg in recording.messages(topic, contract.CONTACT_ONSET)}
    return [by_time.get(float(t)) for t in states.t]


def _order(given, names, where):
    given = list(given)
    if sorted(given) != sorted(names):
        extra = sorted(set(given) - set(names)) or sorted(set(names) - set(given))
        raise TrajectoryError(f"{where}: joints {given} are not those of message 0 "
                              f"(differs in {shown(extra[0])})")
    return [given.index(name) for name in names]


@dataclass
class HingeTrack:
    """A joint-state stream on a model's tree coordinates, what the collision check takes.

    Attributes
    ----------
    t : (s,) ndarray
        s from the first joint state (``t0`` is its stamp).
    theta : (s, n_coords) ndarray
        rad, in ``model.joints`` order.
    omega : (s, n_coords) ndarray or list of None
        rad/s; ``[None] * s`` when the stream has no velocities (the check
        then takes finite differences).
    t0 : float
        s.
    """

    t: np.ndarray
    theta: np.ndarray
    omega: object
    t0: float


def hinge_track(states: JointStates, model, path, scene_name: str = "") -> HingeTrack:
    """``states`` on ``model``'s tree hinges: the tree hinges the stream
    carries, the others solved from the loop closure (any hinge set the
    closure completes, as the collision monitor takes).

    Raises
    ------
    TrajectoryError
        A joint that is no hinge of the model, or a hinge set that does not
        determine the tree's angles (naming a hinge).
    """
    from ..sensing import TreeCoordinates

    known = [model.hinges[h].name for h in hinge_order(model)]
    label = f"scene {scene_name}" if scene_name else "the scene"
    unknown = [name for name in states.names if name not in known]
    if unknown:
        raise TrajectoryError(f"{path}: /joint_states names are not the hinges of {label}: "
                              f"joint {shown(unknown[0])} is not a hinge of {label} "
                              f"(hinges: {', '.join(known)})")
    coordinates = TreeCoordinates(model)
    s = len(states.t)
    theta = np.empty((s, model.n_coords))
    omega = np.empty((s, model.n_coords)) if states.velocity is not None else [None] * s
    try:
        for j in range(s):
            velocity = None if states.velocity is None else states.velocity[j]
            theta[j], w = coordinates(states.names, states.position[j], velocity)
            if w is not None:
                omega[j] = w
    except TrajectoryError as e:
        raise TrajectoryError(f"{path}: /joint_states of {label}, message {j}: {e}") from None
    return HingeTrack(states.t - states.t[0], theta, omega, float(states.t[0]))

"""The wire form of the messages a deployment sends at every sample, and of
``/tf_static``: the one place they are built, for the dynamics node (which
publishes these bytes as they are) and for recordings alike.

For one model the byte layout of ``/joint_states``, ``/panel_deploy/panels``,
``/tf`` and ``/clock`` never changes from sample to sample (same names, same
element counts, same string lengths), so each is a precomputed
:mod:`struct` format into which a sample puts its stamp, angles, rates,
torques and poses: one ``struct.pack`` per message instead of the generic
field-by-field serializer, which costs more than the simulation it records
(measured 2026-11-26 on the paper scene: 48 us per sample for the four
messages here, 528 us with rosbags building and serializing them, 11x).
The bytes equal ``rosbags``' ``serialize_cdr`` of the messages that
:mod:`panel_deploy.record.messages` builds from the same values, and rclpy
decodes them (the tests check both). Frames are the URDF's link names and
``world``, after an optional prefix (the dynamics node's ``frame_prefix``);
the poses of ``/tf`` are :func:`panel_deploy.frames.tree_transforms`.

CDR as ROS 2 writes it: the 4-byte encapsulation header ``00 01 00 00``
(CDR, little endian), then the fields in definition order, each primitive
aligned to its size counted from the end of that header; a string is its
byte length with the terminating NUL (uint32), the bytes and the NUL; a
sequence is its element count (uint32) and its elements.
"""

from __future__ import annotations

import struct

import numpy as np

from ..frames import ground_transform, quaternions, tree_transforms
from ..model import hinge_order
from . import PANEL_COLOUR, WORLD, nanoseconds

ENCAPSULATION = b"\x00\x01\x00\x00"


class Layout:
    """A CDR byte layout built field by field; :meth:`pack` fills in the variable fields.

    Constant fields keep the value given when they are added; a variable
    field (value None) gets a slot, an index into the values :meth:`pack` takes.
    """

    def __init__(self):
        self._fmt = ["<"]
        self._args = []
        self._slots = []        # argument index of every variable field, in slot order
        self._offset = 0

    def _align(self, size: int) -> None:
        pad = -self._offset % size
        if pad:
            self._fmt.append(f"{pad}x")
            self._offset += pad

    def _field(self, code: str, size: int, value) -> None:
        self._align(size)
        self._fmt.append(code)
        self._offset += size
        if value is None:
            self._slots.append(len(self._args))
        self._args.append(value)

    def int32(self, value=None):
        self._field("i", 4, value)

    def uint32(self, value=None):
        self._field("I", 4, value)

    def float32(self, value=None):
        self._field("f", 4, value)

    def float64(self, value=None):
        self._field("d", 8, value)

    def boolean(self, value: bool):
        self._field("?", 1, value)

    def string(self, text: str):
        data = text.encode() + b"\0"
        self.uint32(len(data))
        self._fmt.append(f"{len(data)}s")
        self._args.append(data)
        self._offset += len(data)

    def empty_sequence(self):
        self.uint32(0)

    def float64s(self, n: int):
        """A float64[] of ``n`` variable elements."""
        self.uint32(n)
        for _ in range(n):
            self.float64()

    def time(self):
        """A variable ``builtin_interfaces/Time``: two slots, sec and nanosec."""
        self.int32()
        self.uint32()

    def header(self, frame: str):
        self.time()
        self.string(frame)

    def compile(self) -> "Layout":
        """Fix the layout: no field can be added after this."""
        self._struct = struct.Struct("".join(self._fmt))
        return self

    def pack(self, values) -> bytes:
        """The message bytes (encapsulation header included) with ``values`` in the slots, in order."""
        args = list(self._args)
        for i, v in zip(self._slots, values):
            args[i] = v
        return ENCAPSULATION + self._struct.pack(*args)


def _stamp(t: float) -> tuple:
    ns = nanoseconds(t)
    return ns // 1_000_000_000, ns % 1_000_000_000


class SampleEncoder:
    """CDR bytes of one model's per-sample messages (see the module doc).

    Parameters
    ----------
    model : Model
    prefix : str
        Put before every frame name (``array1/``); empty for none.

    Attributes
    ----------
    names : list of str
        The joint names of ``/joint_states``, in order: every hinge, tree
        coordinates first, then the cut hinges (:func:`~panel_deploy.model.hinge_order`).
    """

    def __init__(self, model, prefix: str = ""):
        self.model = model
        self.prefix = prefix
        self.names = names = [model.hinges[h].name for h in hinge_order(model)]
        self._clock = Layout()
        self._clock.time()
        self._clock.compile()

        js = Layout()
        js.header("")
        js.uint32(len(names))
        for name in names:
            js.string(name)
        for _ in range(3):  # position, velocity, effort
            js.float64s(len(names))
        self._joint_state = js.compile()

        panels = Layout()
        panels.uint32(model.n_bodies)
        for b, body in enumerate(model.bodies):
            panels.header(prefix + WORLD)
            panels.string("panels")
            panels.int32(b)
            panels.int32(1)      # CUBE
            panels.int32(0)      # ADD
            for _ in range(7):   # pose: position x y z, orientation x y z w
                panels.float64()
            for size in body.size:
                panels.float64(float(size))
            for c in PANEL_COLOUR:
                panels.float32(c)
            panels.int32(0)      # lifetime: 0 = forever
            panels.uint32(0)
            panels.boolean(False)  # frame_locked
            panels.empty_sequence()  # points
            panels.empty_sequence()  # colors
            panels.string("")      # texture_resource
            panels.int32(0)        # texture: header stamp, frame, format, data
            panels.uint32(0)
            panels.string("")
            panels.string("")
            panels.empty_sequence()
            panels.empty_sequence()  # uv_coordinates
            panels.string(body.name)  # text
            panels.string("")      # mesh_resource
            panels.string("")      # mesh_file: filename, data
            panels.empty_sequence()
            panels.boolean(False)  # mesh_use_embedded_materials
        self._panels = panels.compile()
        self._tf = self._transforms([(model.hinges[h].body_a, model.hinges[h].body_b)
                                     for h in model.joints])
        self._onsets = {}  # contact pair index (-1: none) -> its ContactOnset layout

    def _transforms(self, pairs) -> Layout:
        """A TFMessage of one transform per (parent, child) body pair (-1: ``world``)."""
        frame = [self.prefix + b.name for b in self.model.bodies]
        tf = Layout()
        tf.uint32(len(pairs))
        for a, b in pairs:
            tf.header(self.prefix + WORLD if a < 0 else frame[a])
            tf.string(frame[b])
            for _ in range(7):   # translation x y z, rotation x y z w
                tf.float64()
        return tf.compile()

    def encode(self, samples) -> list:
        """``(clock, joint_state, panels, tf)`` bytes of every sample, a
        :class:`~panel_deploy.dynamics.deployment.Sample` (or any object with its fields).

        ``theta``, ``omega``, ``torque``: every joint in :attr:`names` order
        (rad, rad/s, N m); ``rotation`` (nb, 3, 3) and ``position`` (nb, 3,
        m): the body (centroid) poses in ``world``. The panels are CUBEs at
        the body poses; ``/tf`` gives every tree joint's child link in its
        parent link's frame. Samples are encoded together: one vectorised
        pose and quaternion computation for all.
        """
        k, nb = len(samples), self.model.n_bodies
        R = np.array([s.rotation for s in samples], dtype=float)          # (k, nb, 3, 3)
        c = np.array([s.position for s in samples], dtype=float)          # (k, nb, 3)
        _, _, R_rel, p_rel = tree_transforms(self.model, R, c)
        q = quaternions(np.concatenate([R, R_rel], axis=1).reshape(-1, 3, 3))
        q = q.reshape(k, -1, 4).tolist()
        c, p_rel = c.tolist(), p_rel.tolist()
        out = []
        for j, s in enumerate(samples):
            stamp = _stamp(s.t)
            panels, tf = [], []
            for xyz, quat in zip(c[j], q[j][:nb]):
                panels += (*stamp, *xyz, *quat)
            for xyz, quat in zip(p_rel[j], q[j][nb:]):
                tf += (*stamp, *xyz, *quat)
            js = (*stamp, *np.asarray(s.theta, dtype=float).tolist(),
                  *np.asarray(s.omega, dtype=float).tolist(),
                  *np.asarray(s.torque, dtype=float).tolist())
            out.append((self._clock.pack(stamp), self._joint_state.pack(js),
                        self._panels.pack(panels), self._tf.pack(tf)))
        return out

    def onset(self, t: float, onset) -> bytes:
        """``dynamics/contact_onsets`` bytes of the sample at ``t`` (s): ``onset``
        is the row of ``SimulationResult.contact_onsets`` (``ONSET_COLUMNS``)
        of the interval that ends there; pair -1 (no onset) gives empty names.
        One layout per contact pair, built when the pair first comes to press."""
        k = int(onset[2])
        layout = self._onsets.get(k)
        if layout is None:
            layout = self._onsets[k] = Layout()
            layout.header(self.prefix + WORLD)
            a, b = self.model.contact_pairs[k] if k >= 0 else (None, None)
            for body in (a, b):
                layout.string("" if body is None else self.model.bodies[body].name)
            for _ in range(8):   # t, speed, point x y z, normal x y z
                layout.float64()
            layout.compile()
        t_onset, speed, _, *point_normal = np.asarray(onset, dtype=float).tolist()
        return layout.pack((*_stamp(t), t_onset, speed, *point_normal))

    def tf(self, rotation, position, t: float) -> bytes:
        """``/tf`` bytes of one sample's body poses (as :meth:`encode` makes them)."""
        _, _, R_rel, p_rel = tree_transforms(self.model, rotation, position)
        stamp = _stamp(t)
        values = []
        for xyz, quat in zip(p_rel.tolist(), quaternions(R_rel).tolist()):
            values += (*stamp, *xyz, *quat)
        return self._tf.pack(values)

    def tf_static(self) -> bytes:
        """``/tf_static``: ``world`` -> the ground body's link (the URDF's fixed joint), stamped 0."""
        R, p = ground_transform(self.model)
        layout = self._transforms([(-1, self.model.ground)])
        return layout.pack((0, 0, *p.tolist(), *quaternions(R[None])[0].tolist()))

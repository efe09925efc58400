"""A deployment computed block by block and handed out sample by sample, as
the dynamics node streams it and recordings write it."""

from __future__ import annotations

import threading
from dataclasses import replace
from typing import NamedTuple

import numpy as np

from ..model import Model
from .pack import pack
from .report import hinge_states
from .result import SimulationResult, Status, concatenate
from .simulate import simulate_segments

#: Samples per integrator block: 50 ms of simulated time at 200 Hz, small
#: enough that the first message leaves within milliseconds of the request.
BLOCK_SAMPLES = 10


class Sample(NamedTuple):
    """One instant of a deployment, every hinge in :func:`hinge_states` order."""

    t: float              #: s
    theta: np.ndarray     #: rad
    omega: np.ndarray     #: rad/s
    torque: np.ndarray    #: N m
    rotation: np.ndarray  #: (nb, 3, 3) body orientations in the ground frame
    position: np.ndarray  #: (nb, 3) body centroids, m
    #: The fastest panel contact onset since the last sample, a row of
    #: ``SimulationResult.contact_onsets`` (pair -1: none)
    onset: np.ndarray | None = None


class Deployment:
    """A deployment computed block by block and handed out sample by sample.

    Iterating yields :class:`Sample` as soon as its block is integrated; the
    blocks continue one integration, so the samples are those of
    :func:`~panel_deploy.dynamics.simulate` with the same settings. After the
    iteration, :attr:`result` is the whole run (what was computed, when
    stopped early). :meth:`stop` (from any thread) ends it at the next block.
    """

    def __init__(self, model: Model, settings, block: int = BLOCK_SAMPLES):
        self.model = model
        self.settings = settings
        self.block = block
        self.names = None
        self.blocks: list = []
        self.stopped = False
        #: Set by :meth:`stop`; wait on it to sleep no longer than the run lasts.
        self.stopping = threading.Event()

    def stop(self) -> None:
        self.stopping.set()

    def __iter__(self):
        segments = simulate_segments(self.model, self.settings, segment_samples=self.block)
        packed = pack(self.model)
        try:
            for block in segments:
                self.blocks.append(block)
                names, theta, omega, torque = hinge_states(self.model, block, packed)
                self.names = names
                for j in range(len(block.t)):
                    yield Sample(float(block.t[j]), theta[j], omega[j], torque[j],
                                 block.rotation[j], block.position[j], block.contact_onsets[j])
                if self.stopping.is_set():
                    self.stopped = True
                    return
        finally:
            segments.close()

    @property
    def result(self) -> SimulationResult | None:
        """The samples computed so far as one result (None before the first block)."""
        if not self.blocks:
            return None
        result = concatenate(self.blocks)
        if self.stopped and result.success:
            result = replace(result, success=False, status=Status.STOPPED,
                             message=f"stopped at t = {result.t[-1]:.6g} s")
        return result

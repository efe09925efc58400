"""Where evaluations run: in-process, on a local process pool, or on Dask.

All three backends run the same picklable task, :func:`evaluate_job`, so a
result does not depend on where it was computed. :class:`Evaluator` adds
the cache by K and the evaluation budget on top of any backend.
"""

from __future__ import annotations

import multiprocessing
import multiprocessing.connection
import os
import signal
import threading
import time
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..errors import OptimisationError
from .evaluate import Evaluation, evaluate, run_deployment

#: Seconds to wait for a Dask scheduler before giving up.
CONNECT_TIMEOUT = 5.0


@dataclass(frozen=True)
class Job:
    """What every evaluation of one optimisation shares (sent once per worker)."""

    model: object
    scene: object
    evaluation: Callable = run_deployment


def evaluate_job(job: Job, k, c=None) -> Evaluation:
    """:func:`~panel_deploy.optimise.evaluate.evaluate` for one K of ``job``."""
    return evaluate(job.model, k, job.scene, c=c, evaluation=job.evaluation)


_WORKER_JOB = None


def _init_worker(job):
    global _WORKER_JOB
    _WORKER_JOB = job
    _guard_worker()


def _guard_worker():
    # Ctrl-C and timeout(1) signal the whole process group: a worker ended by
    # that would break the pool under the parent, which is saving the best K
    # so far. The parent ends the workers (ProcessBackend.close), or, if it
    # is gone first (a worker it was starting when interrupted is never told
    # to stop), the watch below does.
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    threading.Thread(target=_exit_with_parent, daemon=True).start()


def _exit_with_parent():
    multiprocessing.connection.wait([multiprocessing.parent_process().sentinel])
    os._exit(1)


def _evaluate_in_worker(kc):
    return evaluate_job(_WORKER_JOB, *kc)


class SerialBackend:
    """Evaluations one after the other in this process."""

    workers = 1

    def __init__(self, job: Job):
        self.job = job

    def map(self, kcs):
        return [evaluate_job(self.job, k, c) for k, c in kcs]

    def close(self):
        pass


class ProcessBackend:
    """A pool of local worker processes (:func:`_process_pool`), the job sent once to each."""

    def __init__(self, job: Job, workers: int):
        self.workers = workers
        self._pool = _process_pool(workers, _init_worker, (job,))

    def map(self, kcs):
        return list(self._pool.map(_evaluate_in_worker, kcs))

    def close(self):
        self._pool.shutdown(wait=True, cancel_futures=True)


class DaskBackend:
    """Evaluations on an existing Dask distributed cluster.

    Parameters
    ----------
    job : Job
        Scattered to every worker once.
    address : str
        Scheduler address, e.g. ``tcp://10.0.0.5:8786``.
    timeout : float
        Seconds to wait for the scheduler.

    Raises
    ------
    OptimisationError
        ``dask_address`` naming the address, if distributed is not installed
        or the scheduler does not answer within ``timeout``.
    """

    def __init__(self, job: Job, address: str, timeout: float = CONNECT_TIMEOUT):
        self._client = _dask_client(address, timeout)
        self.workers = max(1, sum(self._client.nthreads().values()))
        self._job = self._client.scatter([job], broadcast=True)[0]

    def map(self, kcs):
        futures = [self._client.submit(evaluate_job, self._job, k, c, pure=False) for k, c in kcs]
        return self._client.gather(futures)

    def close(self):
        self._client.close()


def _process_pool(workers: int, initializer, initargs=()) -> ProcessPoolExecutor:
    """``workers`` local processes, each set up by ``initializer(*initargs)``.

    The forkserver start method: forking a process that already runs threads
    (numba, a Dask client) can deadlock the child.
    """
    ctx = multiprocessing.get_context("forkserver" if os.name == "posix" else "spawn")
    return ProcessPoolExecutor(workers, mp_context=ctx, initializer=initializer,
                               initargs=initargs)


def _dask_client(address: str, timeout: float):
    """A client of the Dask scheduler at ``address``; OptimisationError naming
    ``dask_address`` if distributed is missing or nothing answers in ``timeout`` s."""
    try:
        from distributed import Client
    except ImportError:
        raise OptimisationError("dask_address: the 'distributed' package is not installed "
                                "(pip install 'dask[distributed]')") from None
    if not isinstance(address, str) or not address.strip():
        raise OptimisationError(f"dask_address: expected a scheduler address such as "
                                f"tcp://host:8786, got {address!r}")
    try:
        return Client(address, timeout=timeout, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as e:
        raise OptimisationError(f"dask_address: cannot reach a Dask scheduler at {address!r} "
                                f"within {timeout:g} s ({type(e).__name__}: {e})") from None


def _worker_count(workers) -> int:
    """``workers`` as a count of processes: 0 or None all cores."""
    if workers is None or workers == 0:
        return os.cpu_count() or 1
    if not isinstance(workers, int) or isinstance(workers, bool) or workers < 0:
        raise OptimisationError(f"workers: expected an integer >= 0, got {workers!r}")
    return workers


def make_backend(job: Job, workers: int | None = None, dask_address: str | None = None):
    """The backend asked for: Dask if ``dask_address``, else ``workers`` local processes.

    ``workers`` 0 or None means all cores; 1 runs in this process.
    """
    if dask_address is not None:
        return DaskBackend(job, dask_address)
    workers = _worker_count(workers)
    return SerialBackend(job) if workers == 1 else ProcessBackend(job, workers)


@contextmanager
def task_map(workers: int | None = None, dask_address: str | None = None):
    """A ``map(fn, items)`` for independent picklable tasks (a ranking's
    screenings, :func:`panel_deploy.ranking.rank_circuits`) where the
    evaluations of :func:`make_backend` would run: on the Dask scheduler at
    ``dask_address``, else on ``workers`` local processes (0 or None: all
    cores; 1: here, one after the other). Its results come in the order of
    ``items``, each as soon as it and those before it are done. The workers
    end with the context.

    Raises
    ------
    OptimisationError
        As :func:`make_backend`.
    """
    if dask_address is not None:
        client = _dask_client(dask_address, CONNECT_TIMEOUT)
        try:
            yield lambda fn, items: (f.result() for f in client.map(fn, list(items), pure=False))
        finally:
            client.close()
        return
    workers = _worker_count(workers)
    if workers == 1:
        yield map
        return
    pool = _process_pool(workers, _guard_worker)
    try:
        yield pool.map
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


class BudgetExhausted(Exception):
    """Raised inside a solver's objective to stop it when the budget is spent;
    ``args``: the new K of the batch that did not fit, and the evaluations left."""


class Cancelled(Exception):
    """Raised inside a solver's objective when the caller asked the search to stop."""


class Evaluator:
    """Cached, budgeted evaluation of batches of K on a backend.

    Parameters
    ----------
    backend : SerialBackend, ProcessBackend or DaskBackend
    max_evaluations : int
        Simulations allowed; cached K are free.
    on_batch : callable, optional
        Called with no argument after each batch (progress reporting).
    stop : callable, optional
        Called with no argument before each batch; True raises :class:`Cancelled`.
    """

    def __init__(self, backend, max_evaluations: int, on_batch=None, stop=None):
        self.backend = backend
        self.max_evaluations = max_evaluations
        self.on_batch = on_batch
        self.stop = stop
        self.cache = {}
        self.history = []
        self.best = None
        #: (evaluations, s since the start) when the first feasible K came back, or None.
        self.first_feasible = None
        self.start = time.perf_counter()

    @property
    def nfev(self) -> int:
        return len(self.history)

    @staticmethod
    def key(k, c=None):
        # Rounded so that K reached by different float paths share an entry.
        kk = tuple(np.round(np.asarray(k, dtype=float), 12))
        return kk if c is None else kk + tuple(np.round(np.asarray(c, dtype=float), 12))

    def map(self, ks, cs=None) -> list:
        """Evaluations of every K of ``ks`` (and damping ``cs``), in order.

        Raises :class:`BudgetExhausted`, before running anything, if the new
        K of the batch do not fit in the budget, and :class:`Cancelled` if
        ``stop`` says so.
        """
        cs = [None] * len(ks) if cs is None else cs
        keys = [self.key(k, c) for k, c in zip(ks, cs)]
        todo = {}
        for key, k, c in zip(keys, ks, cs):
            if key not in self.cache and key not in todo:
                todo[key] = (np.asarray(k, dtype=float), None if c is None else np.asarray(c, float))
        if self.nfev + len(todo) > self.max_evaluations:
            raise BudgetExhausted(len(todo), self.max_evaluations - self.nfev)
        if todo and self.stop is not None and self.stop():
            raise Cancelled
        if todo:
            for key, ev in zip(todo, self.backend.map(list(todo.values()))):
                self.cache[key] = ev
                self.history.append(ev)
                if self.best is None or _better(ev, self.best):
                    self.best = ev
                if self.first_feasible is None and ev.outcome.feasible:
                    self.first_feasible = (self.nfev, self.elapsed)
            if self.on_batch is not None:
                self.on_batch()
        return [self.cache[key] for key in keys]

    @property
    def elapsed(self) -> float:
        return time.perf_counter() - self.start


def _better(a: Evaluation, b: Evaluation) -> bool:
    """Feasible beats infeasible; then the lower f."""
    if a.outcome.feasible != b.outcome.feasible:
        return a.outcome.feasible
    return a.f < b.f

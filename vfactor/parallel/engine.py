"""Where independent pieces of work run: in this process, or on a Dask distributed cluster.

Every batch command reduces its work to independent *units* (a vehicle in a
frame for ``solve``, a track for ``track`` and batch smoothing, one simulated
scene of ``eval``) and hands them to an :class:`Engine`:
``engine.map(function, units)`` yields ``function(unit)`` for every unit, **in
the units' order**, as soon as each result and all results before it are in.
The functions are the same whichever engine runs them, so a run on a cluster
returns exactly what the serial run returns.

:class:`InProcess` (the default) runs the units one after another and needs no
Dask. :class:`DaskEngine` sends them, a few units per task, to the workers of a
``dask.distributed`` cluster: a :class:`~distributed.LocalCluster` of ``workers``
processes on this machine, or an existing cluster's scheduler. A worker that
dies mid-job loses nothing: the scheduler runs its tasks again on another worker
(Dask's own recovery; a task is given up only after ``allowed_failures`` worker
deaths). A unit that fails for its input is no fault of the engine: the unit
functions catch it and return the vehicle's status (``failed``) instead.
"""

from __future__ import annotations

import itertools
import logging
import os
import re
from collections.abc import Callable, Iterable, Iterator
from typing import Any

from vfactor.errors import InputError

__all__ = ["Engine", "InProcess", "DaskEngine", "open_engine", "check_engine_options", "warm_up"]

log = logging.getLogger(__name__)


class Engine:
    """Runs independent units of work; see the module docstring.

    Attributes:
        workers: how many units can run at once (1 in process).
    """

    workers: int = 1

    def map(self, function: Callable[[Any], Any], units: Iterable, progress: Callable[[int, int], None] | None = None,
            total: int | None = None) -> Iterator:
        """``function(unit)`` for every unit, in the units' order.

        Args:
            function: a module-level function (it is pickled for a cluster), deterministic in its unit.
            units: the units (picklable); an iterator is consumed as the work goes on, so that a long job
                need not hold every unit in memory.
            progress: called as ``progress(done, total)`` after each unit whose result is yielded.
            total: the number of units when ``units`` has no length (for ``progress``).
        """
        raise NotImplementedError

    def close(self) -> None:
        """Releases the workers (a local cluster is shut down; an existing one is left running)."""

    def __enter__(self) -> "Engine":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _total(units, total):
    if total is not None:
        return total
    try:
        return len(units)
    except TypeError:
        return 0


class InProcess(Engine):
    """The units one after another in this process (no Dask)."""

    def map(self, function, units, progress=None, total=None):
        total = _total(units, total)
        for done, unit in enumerate(units, 1):
            yield function(unit)
            if progress is not None:
                progress(done, max(total, done))


def _run_chunk(function: Callable, chunk: list) -> list:
    """One Dask task: a few units in a row (the per-task cost of the scheduler is paid once for them)."""
    return [function(unit) for unit in chunk]


def warm_up() -> int:
    """Imports vfactor's solver and runs one small solve, so that a worker's first real unit does not pay the
    imports and the loading of the compiled kernels; returns the process id. Run on every worker as it joins."""
    from vfactor.sim import simulate
    from vfactor.solve import solve_scene

    solve_scene(simulate("intersection_2cam", seed=0, num_frames=1).scene)
    return os.getpid()


class DaskEngine(Engine):
    """Units on a ``dask.distributed`` cluster, in chunks, results in the units' order.

    Args:
        workers: start a :class:`~distributed.LocalCluster` of this many worker processes (one thread each:
            GTSAM and the compiled kernels hold the GIL for most of a solve).
        scheduler: the address of a running scheduler (``tcp://host:8786``, from ``dask scheduler``) instead.
        client: an existing :class:`~distributed.Client` instead (left open by :meth:`close`).
        chunk: units per task; default: enough that a task takes well over the scheduler's per-task cost, few
            enough that the work spreads (``max(1, min(16, total // (8 * workers)))``).
        in_flight: tasks submitted ahead of the results (default 4 per worker): bounds the memory that a long
            job holds, units and results, however many units it has.
        warm: run :func:`warm_up` on every worker before the first task.

    Raises:
        InputError: (field ``--workers`` / ``--scheduler``) Dask is not installed, the number of workers is
            not positive, or the scheduler cannot be reached.
    """

    def __init__(self, workers: int | None = None, scheduler: str | None = None, client=None,
                 chunk: int | None = None, in_flight: int | None = None, warm: bool = True):
        field = "--scheduler" if scheduler else "--workers"
        if sum(x is not None for x in (workers, scheduler, client)) != 1:
            raise InputError(field, "give one of: a number of workers, a scheduler address, a client")
        check_engine_options(workers, scheduler)
        try:
            from distributed import Client, LocalCluster
        except ImportError as exc:
            raise InputError(field, f"this needs Dask ({exc}); install with "
                             "pip install -c constraints.txt -e '.[dask]'") from None
        self._cluster = None
        self._own_client = client is None
        if client is not None:
            self.client = client
        elif scheduler is not None:
            self.client = _connected(Client, scheduler)
        else:
            self._cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                         dashboard_address=":0", silence_logs=logging.ERROR)
            self.client = Client(self._cluster)
        self.workers = max(1, sum(self.client.nthreads().values()))
        self.chunk, self.in_flight = chunk, in_flight
        if warm:
            self.client.register_plugin(_warm_up_plugin(), name="vfactor-warm-up")
        log.info("Dask: %d worker threads (%s)", self.workers, self.client.scheduler.address)

    def map(self, function, units, progress=None, total=None):
        from distributed import as_completed

        total = _total(units, total)
        chunk = self.chunk or max(1, min(16, total // (8 * self.workers)))
        ahead = self.in_flight or 4 * self.workers
        chunks = _chunks(units, chunk)
        pending = as_completed()
        index_of, ready, submitted = {}, {}, 0
        name = f"vfactor-{getattr(function, '__name__', 'unit')}-{os.urandom(16).hex()}"  # os, not uuid: a lighter import

        def submit() -> bool:
            nonlocal submitted
            piece = next(chunks, None)
            if piece is None:
                return False
            future = self.client.submit(_run_chunk, function, piece, pure=False, key=f"{name}-{submitted}")
            index_of[future.key] = submitted
            pending.add(future)
            submitted += 1
            return True

        next_out, done = 0, 0
        # at most `ahead` chunks between the next one to yield and the last submitted: the results that wait for
        # an earlier, slower chunk count too, so a stalled chunk (its worker lost) does not let them pile up
        while submitted - next_out < ahead and submit():
            pass
        try:
            for future in pending:
                try:
                    result = future.result()
                except Exception as exc:  # noqa: BLE001  the unit's own errors come back as they were raised
                    if not _lost(exc):
                        raise
                    raise ConnectionError(f"lost the Dask scheduler at {self.client.scheduler.address} mid-run "
                                          f"({type(exc).__name__}); the work done so far is not written") from None
                ready[index_of.pop(future.key)] = result
                future.release()
                while next_out in ready:
                    for result in ready.pop(next_out):
                        done += 1
                        yield result
                        if progress is not None:
                            progress(done, max(total, done))
                    next_out += 1
                while submitted - next_out < ahead and submit():
                    pass
        finally:
            for future in list(pending.futures):
                future.cancel()

    def close(self) -> None:
        if self._own_client:
            self.client.close()
        if self._cluster is not None:
            self._cluster.close()


#: Seconds to reach a ``--scheduler`` and hear back from it: a port that takes the connection and never answers as
#: Dask does (a dashboard's HTTP port) would hold the command for ever.
CONNECT_TIMEOUT = 10.0


def _connected(client_class, scheduler: str):
    """A client of the scheduler at ``scheduler``, or a one-line InputError (field ``--scheduler``) within
    :data:`CONNECT_TIMEOUT` seconds: not reached, not a Dask scheduler (its answer is not Dask's), or no answer."""
    import threading

    outcome: dict = {}

    def connect():
        try:
            outcome["client"] = client_class(scheduler, timeout=f"{CONNECT_TIMEOUT / 2:g}s")
        except BaseException as exc:  # noqa: BLE001  reported below, in the caller's thread
            outcome["error"] = exc

    thread = threading.Thread(target=connect, name="vfactor-dask-connect", daemon=True)
    thread.start()
    thread.join(CONNECT_TIMEOUT)
    if thread.is_alive():
        raise InputError("--scheduler", f"no answer from a Dask scheduler at {scheduler} within "
                                        f"{CONNECT_TIMEOUT:g} s (is it the scheduler's port, 8786 by default?)")
    error = outcome.get("error")
    if isinstance(error, (OSError, TimeoutError)):
        raise InputError("--scheduler", f"cannot reach the Dask scheduler at {scheduler}: {error}") from None
    if error is not None:  # a MemoryError from a length read off another protocol's bytes, a ValueError, ...
        raise InputError("--scheduler", f"{scheduler} does not answer as a Dask scheduler "
                                        f"({type(error).__name__}: {str(error)[:120]})") from None
    return outcome["client"]


def _lost(exc: BaseException) -> bool:
    """Whether a task's failure is the cluster's (the scheduler or its connection lost), not the unit's."""
    from distributed.client import FutureCancelledError

    try:
        from distributed.comm.core import CommClosedError
    except ImportError:  # pragma: no cover  older distributed
        CommClosedError = OSError  # noqa: N806
    return isinstance(exc, (FutureCancelledError, CommClosedError))


def _warm_up_plugin():
    """A worker plugin (:meth:`distributed.Client.register_plugin`) running :func:`warm_up` on every worker,
    also on workers that join later (one restarted after a crash)."""
    from distributed.diagnostics.plugin import WorkerPlugin

    class WarmUp(WorkerPlugin):
        idempotent = True

        def setup(self, worker) -> None:
            warm_up()

    return WarmUp()


def _chunks(units: Iterable, size: int) -> Iterator[list]:
    iterator = iter(units)
    while piece := list(itertools.islice(iterator, size)):
        yield piece


_ADDRESS = r"(?:[a-z]+://)?(?:\[[0-9a-fA-F:.]+\]|[^\s:/\[\]]+):\d{1,5}/?"  # [scheme://]host:port, IPv6 in []


def check_engine_options(workers: int | None = None, scheduler: str | None = None) -> None:
    """Checks a command's ``--workers N`` / ``--scheduler ADDRESS`` before any work (starts nothing).

    Raises:
        InputError: both given, or a number of workers below 1.
    """
    if workers is not None and scheduler is not None:
        raise InputError("--workers", "give --workers (a local cluster) or --scheduler (an existing one), not both")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise InputError("--workers", f"expected an integer >= 1, got {workers}")
    if scheduler is not None and not re.fullmatch(_ADDRESS, str(scheduler)):
        raise InputError("--scheduler", f"expected the scheduler's address, as tcp://host:8786, got {scheduler!r}")


def open_engine(workers: int | None = None, scheduler: str | None = None) -> Engine:
    """The engine of a command's ``--workers N`` / ``--scheduler ADDRESS``: in process when neither is given.

    Raises:
        InputError: see :func:`check_engine_options` and :class:`DaskEngine`.
    """
    check_engine_options(workers, scheduler)
    if workers is None and scheduler is None:
        return InProcess()
    return DaskEngine(workers=workers, scheduler=scheduler)

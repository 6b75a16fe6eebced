"""Rooms as tasks on Dask distributed: an embedded local cluster (worker processes on 127.0.0.1, started
and stopped here), or an existing scheduler. Results come back as they finish; a worker that dies
mid-task has its room rerun elsewhere by the scheduler (up to ``distributed.scheduler.allowed-failures``
times), and whatever else goes wrong with a task becomes that room's failure, not the site's.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable, Iterator, Sequence

from runtime.errors import UsageError
from runtime.site.rooms import plan_room
from runtime.site.sitefile import RoomSpec

#: How long to wait for an existing scheduler to answer.
CONNECT_TIMEOUT_S = 10


@contextlib.contextmanager
def dask_client(workers: int, scheduler: str | None = None) -> Iterator[object]:
    """A ``distributed.Client``: on a new local cluster of ``workers`` single-threaded worker processes
    (scheduler and workers on 127.0.0.1, ports the OS picks, no dashboard), stopped on leaving; or
    connected to ``scheduler`` (``tcp://HOST:PORT``), which is left running."""
    from distributed import Client, LocalCluster

    if scheduler is not None:
        try:
            client = Client(scheduler, timeout=f"{CONNECT_TIMEOUT_S}s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise UsageError(f"--scheduler: cannot connect to {scheduler} ({type(exc).__name__}: "
                             f"{str(exc).splitlines()[0] if str(exc) else 'no answer'}); expected the address "
                             "of a running `dask scheduler`, e.g. tcp://127.0.0.1:8786") from None
        with client:
            yield client
        return
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                      scheduler_port=0, dashboard_address=None, silence_logs=logging.ERROR) as cluster, \
            Client(cluster) as client:
        yield client


def run_rooms(client, specs: Sequence[RoomSpec], cache_dir: str | None,
              done: Callable[[RoomSpec, dict], None]) -> None:
    """Submit every room, and call ``done(spec, result)`` for each as it finishes (in the order they
    finish). A task that raises (the scheduler gave up on it after workers died under it, or the
    connection was lost) is reported as a failed room."""
    from distributed import as_completed

    futures = {client.submit(plan_room, spec, cache_dir, key=f"plan-room-{spec.name}-{spec.fingerprint}",
                             pure=False): spec for spec in specs}
    for future in as_completed(futures):
        spec = futures.pop(future)
        try:
            result = future.result()
            # let go of it: a finished room whose result sits on a worker that dies later is not recomputed
            future.release()
        except Exception as exc:  # KilledWorker, CommClosedError, CancelledError: the room failed, not the site
            first = str(exc).splitlines()[0] if str(exc) else ""
            result = {"name": spec.name, "fingerprint": spec.fingerprint, "status": "failed",
                      "error": f"{type(exc).__name__}: {first}".rstrip(": "), "seconds": None}
        done(spec, result)

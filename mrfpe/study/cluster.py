"""Trials on a running ``dask.distributed`` cluster, written on the client as they arrive."""

from __future__ import annotations

import os
import sys
import traceback
import uuid
from collections.abc import Callable, Mapping
from typing import Any

import xarray as xr

from mrfpe.netcdf import DiskFullError
from mrfpe.study.seeds import Task
from mrfpe.study.spec import Study
from mrfpe.study.trial import execute

__all__ = ["CONNECT_TIMEOUT_S", "connect", "execute_pickled", "run_on_cluster"]

#: How long to wait for the scheduler before giving up: long enough for a loaded
#: scheduler, short enough that a typo in the address is reported promptly.
CONNECT_TIMEOUT_S = 5.0


def connect(address: str, timeout: float = CONNECT_TIMEOUT_S) -> Any:
    """A ``distributed.Client`` for ``address``, or ``ValueError`` after ``timeout`` seconds."""
    try:
        from distributed import Client
    except ImportError:  # pragma: no cover - depends on the install
        raise ValueError("--scheduler needs dask.distributed: pip install 'mrfpe[dist]'") \
            from None
    if not isinstance(address, str) or not address.strip():
        raise ValueError(f"--scheduler expects an address like tcp://HOST:8786; got {address!r}")
    import copy

    import dask

    before = copy.deepcopy(dask.config.config)
    clients = _registered_clients()
    known = set(clients)
    try:
        return Client(address, timeout=timeout)
    except Exception as exc:  # also what a server that is not dask makes the client raise
        # (a MemoryError for a garbage frame length, a protocol error, ...). A client that
        # failed to start has already made itself dask's default scheduler: undo that, or
        # every later dask computation in the process asks for a client that is not there.
        dask.config.config.clear()
        dask.config.config.update(before)
        for key in set(clients) - known:  # nor may it stay registered as the default client
            clients.pop(key, None)
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        if len(reason) > 160:
            reason = reason[:157] + "..."
        raise ValueError(f"--scheduler {address}: no dask scheduler reachable within "
                         f"{timeout:g} s ({type(exc).__name__}: {reason})") from None


def _registered_clients() -> dict:
    """distributed's registry of live clients (what dask falls back to as the default
    scheduler); an empty dict where this version keeps none."""
    try:
        from distributed.client import _global_clients
    except ImportError:  # pragma: no cover - other distributed layouts
        return {}
    return _global_clients


def execute_pickled(blob: bytes, study_name: str, config: dict, repeat: int, seed: int,
                    threads_by_host: Mapping[str, int] | None = None) -> xr.Dataset:
    """:func:`mrfpe.study.trial.execute` of a cloudpickled trial function, on a worker."""
    import cloudpickle

    threads = None
    if threads_by_host:
        from distributed import get_worker

        threads = threads_by_host.get(get_worker().address.rsplit(":", 1)[0])
    return execute(cloudpickle.loads(blob), study_name, config, repeat, seed, threads)


def _threads_by_host(client: Any) -> dict[str, int]:
    """Kernel threads per task on each host: its cores over the task slots it runs.

    Two workers of one thread each on a two-core machine give one numba thread
    per trial, not two (which would run four busy threads on two cores).
    """
    workers = client.scheduler_info(n_workers=-1)["workers"]
    cores = client.run(os.cpu_count)
    slots: dict[str, int] = {}
    host_cores: dict[str, int] = {}
    for address, info in workers.items():
        host = address.rsplit(":", 1)[0]
        slots[host] = slots.get(host, 0) + int(info.get("nthreads", 1))
        host_cores[host] = int(cores.get(address) or 1)
    return {h: max(1, host_cores[h] // max(1, n)) for h, n in slots.items()}


def _pickled_trial(study: Study) -> bytes:
    import cloudpickle

    # The trial function travels as cloudpickle bytes, unpickled inside the task: a study
    # loaded from a file is not importable on the workers, so its module goes by value,
    # and any unpickling error becomes a failed trial instead of a stuck worker.
    module = sys.modules.get(study.trial.__module__)
    by_value = module is not None and not study.trial.__module__.startswith("mrfpe.")
    if by_value:
        cloudpickle.register_pickle_by_value(module)
    try:
        return cloudpickle.dumps(study.trial)
    finally:
        if by_value:
            cloudpickle.unregister_pickle_by_value(module)


def run_on_cluster(study: Study, pending: list[Task], client: Any,
                   finish: Callable[[Task, xr.Dataset], None],
                   fail: Callable[[Task, str], None], tick: Callable[[], None]) -> None:
    """Submit every pending trial; ``finish`` each result (or ``fail`` it) as it arrives."""
    from distributed import as_completed

    blob = _pickled_trial(study)
    threads = _threads_by_host(client)
    futures = {}
    for task in pending:
        key = f"{study.name}-{task.stem}-{task.hash}-{uuid.uuid4().hex[:8]}"
        fut = client.submit(execute_pickled, blob, study.name, task.config, task.repeat,
                            task.seed, threads, pure=False, key=key)
        futures[fut] = task
    try:
        for fut in as_completed(list(futures)):
            task = futures.pop(fut)
            try:
                finish(task, fut.result())
            except DiskFullError:
                raise  # stop: no further result could be written either
            except Exception:
                fail(task, traceback.format_exc())
            fut.release()
            tick()
    except BaseException:
        client.cancel(list(futures))
        raise

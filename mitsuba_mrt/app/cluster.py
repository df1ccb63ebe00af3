"""The Dask cluster of the ``batch`` command, lent to ``bench`` too.

:func:`cluster_client` connects to a running scheduler or starts a
LocalCluster and says how Dr.Jit's threads are split; :func:`cluster_map`
runs another command's calls on that cluster (``bench --workers/--scheduler``:
one call per point); :func:`set_jit_threads` is what a worker does before a
task.  This is the only module that imports Dask (``distributed``, the
``batch`` extra), on first use, in :func:`require_distributed`.
"""

from __future__ import annotations

import importlib.util
import logging
import os
import uuid
from contextlib import contextmanager

from ..errors import MRTError, one_line
from ..runtime import configure, threads

#: The one-line error without the extra installed (``{command}``: batch, bench).
DASK_MISSING = "the {command} command needs Dask: pip install mitsuba-mrt[batch]"


def require_distributed(command: str = "batch"):
    """The ``distributed`` module, or a one-line MRTError naming ``command``'s extra."""
    try:
        import distributed
    except ImportError:
        raise MRTError(DASK_MISSING.format(command=command)) from None
    return distributed


def check_cluster_options(scheduler: str | None, workers: int | None,
                          command: str = "batch") -> None:
    """Dask is installed, and ``--scheduler``/``--workers`` make sense (one-line MRTError)."""
    require_distributed(command)
    if workers is not None and workers < 1:
        raise MRTError(f"--workers must be >= 1, got {workers}")
    if workers is not None and scheduler:
        raise MRTError("--workers sizes the local cluster; with --scheduler the "
                       "cluster's own workers run the tasks")


def _cores() -> int:
    return os.cpu_count() or 1


@contextmanager
def cluster_client(scheduler: str | None, workers: int | None, echo):
    """A Dask client: on the cluster at ``scheduler``, or on a new LocalCluster.

    Yields ``(client, jit_threads)`` with ``jit_threads`` what
    :func:`set_jit_threads` sets Dr.Jit's thread count to on a worker.  The
    client is not made the process's default: a caller's own client stays
    its default.
    """
    distributed = require_distributed()
    if scheduler:
        try:
            client = distributed.Client(scheduler, timeout="20s", set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise MRTError(f"cannot connect to the Dask scheduler at {scheduler}: "
                           f"{one_line(exc)}") from None
        try:
            jit_threads = _remote_jit_threads(client)
            info = client.scheduler_info(n_workers=-1)["workers"]
            counts = sorted(set(jit_threads.values()))
            line = (f"dask: scheduler {scheduler}, {len(info)} workers "
                    f"({sum(w['nthreads'] for w in info.values())} threads)"
                    + (f", Dr.Jit threads per worker: cores of its host // its workers' "
                       f"threads = {'/'.join(map(str, counts))}" if counts else
                       "; no workers yet, tasks wait for them"))
            echo(line + _dashboard(client))
            yield client, jit_threads
        finally:
            client.close()
        return
    n = workers or _cores()
    jit_threads = max(1, _cores() // n)
    # a free port on this machine only; without bokeh the page says to install it
    with _environment(worker_environment(jit_threads)):  # what the workers start with
        cluster = distributed.LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                           dashboard_address="127.0.0.1:0",
                                           silence_logs=logging.ERROR)
    try:
        client = distributed.Client(cluster, set_as_default=False)
        try:
            echo(f"dask: local cluster of {n} worker processes x 1 thread, Dr.Jit "
                 f"{jit_threads} thread{'s' if jit_threads > 1 else ''} each "
                 f"({_cores()} cores // {n} workers)" + _dashboard(client))
            yield client, jit_threads
        finally:
            client.close()
    finally:
        cluster.close()


#: The BLAS libraries' thread counts, which they read when they are loaded.
BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def worker_environment(threads: int) -> dict[str, str]:
    """The environment a local worker process starts with: its BLAS threads
    its share of the cores (Dask's default is one each, whatever the share).

    Examples
    --------
    >>> worker_environment(2)["OPENBLAS_NUM_THREADS"]
    '2'
    """
    return {name: str(threads) for name in BLAS_THREADS}


@contextmanager
def _environment(values: dict[str, str]):
    """``os.environ`` with ``values`` inside the block, as it was after it.

    Dask's worker processes inherit this process's environment, and its own
    defaults for them (one BLAS thread) give way to a variable set here.
    """
    before = {name: os.environ.get(name) for name in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for name, value in before.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def _dashboard(client) -> str:
    try:
        link = client.dashboard_link
    except Exception:  # noqa: BLE001 - no dashboard is fine
        link = None
    if not link:
        return "; no dashboard"
    return f"; dashboard {link}" + ("" if importlib.util.find_spec("bokeh") else
                                    " (it needs bokeh: pip install bokeh)")


def _remote_jit_threads(client) -> dict[str, int]:
    """Per worker: its host's cores // the threads of that host's workers."""
    info = client.scheduler_info(n_workers=-1)["workers"]
    if not info:
        return {}
    cores = client.run(os.cpu_count)
    threads_on_host: dict[str, int] = {}
    for address, w in info.items():
        threads_on_host[w["host"]] = threads_on_host.get(w["host"], 0) + w["nthreads"]
    return {address: max(1, (cores.get(address) or 1) // threads_on_host[w["host"]])
            for address, w in info.items()}


# -- on a worker -------------------------------------------------------------------------------


def set_jit_threads(jit_threads) -> None:
    """Dr.Jit's thread count and the package's pool
    (:func:`mitsuba_mrt.runtime.threads.use_threads`) for this worker: its
    share of the cores, an int or per worker address."""
    if isinstance(jit_threads, dict):
        try:
            jit_threads = jit_threads.get(require_distributed().get_worker().address)
        except (MRTError, ValueError):  # not on a Dask worker
            jit_threads = None
    if jit_threads:
        import drjit as dr  # heavy: imported on first use, as job.py imports Mitsuba

        if dr.thread_count() != jit_threads:
            dr.set_thread_count(int(jit_threads))
        threads.use_threads(int(jit_threads))


def _call_on_worker(fn, args: tuple, jit_threads):
    """``fn(*args)`` on a worker, in a process tuned and with Dr.Jit's threads set as
    :func:`mitsuba_mrt.app.tasks.run_task` does; ``fn`` activates its own variant."""
    configure()
    set_jit_threads(jit_threads)
    return fn(*args)


# -- other commands' tasks on the same cluster ----------------------------------------------


@contextmanager
def cluster_map(scheduler: str | None = None, workers: int | None = None, echo=print,
                command: str = "bench"):
    """A Dask cluster for another command's tasks (``bench``: one per point).

    The cluster is that of :func:`mitsuba_mrt.app.batch.run_batch` (``scheduler``,
    or a LocalCluster of ``workers`` processes); yields ``map_calls(fn, calls)``,
    which submits ``fn(*call)`` for every tuple of ``calls`` (``fn`` importable
    on the workers) and yields ``(index, result)`` as each finishes.  A call that
    raises, once its retries are spent, raises here; the others are cancelled.
    """
    check_cluster_options(scheduler, workers, command)

    def map_calls(fn, calls):
        tag = uuid.uuid4().hex[:8]
        futures = {client.submit(_call_on_worker, fn, tuple(call), jit_threads,
                                 key=f"{command}-{k}-{tag}", retries=2, pure=False): k
                   for k, call in enumerate(calls)}
        try:
            for future in as_completed(list(futures), loop=client.loop):
                yield futures.pop(future), future.result()
        finally:
            if futures:
                client.cancel(list(futures))

    as_completed = require_distributed(command).as_completed
    with cluster_client(scheduler, workers, echo) as (client, jit_threads):
        yield map_calls

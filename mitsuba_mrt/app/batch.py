"""The ``batch`` command: many ``render`` jobs spread over a Dask cluster.

A batch is one task per (scene, combination of ``-D`` values).  Each task
is :func:`mitsuba_mrt.app.job.run_render_job` on a worker, writing the same
files as ``render`` into its own folder ``OUT/<scene>_<name>=<value>.../``
(``OUT/<scene>/`` when no ``-D`` has several values); the task returns a
small row of the batch table ``OUT/batch.csv``.  With exactly one varying
parameter the frames of each scene also become ``OUT/<scene>.gif``.

Nothing is lost: a task whose ``<stem>.json`` exists (written last, with
the images, as one atomic set) and matches the request is skipped on a
rerun; a task on a worker that dies runs again on another; a task that
fails records its one-line error and the others go on.

The pure pieces (:func:`parse_values`, :class:`Sweep`, :func:`plan_tasks`,
:func:`run_task`, :func:`write_table`) need no Dask; :func:`run_batch`,
the driver, imports ``dask.distributed`` (the ``batch`` extra).
:func:`cluster_map` lends the same cluster to another command's tasks:
``bench --workers/--scheduler`` measures its points on it.
"""

from __future__ import annotations

import csv
import itertools
import json
import math
import os
import re
import socket
import sys
import time
import uuid
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import MRTError, one_line
from ..imageio import atomic_path

#: The batch table, in the output folder.
TABLE_NAME = "batch.csv"
#: Most tasks one batch may plan (a typo in a range should not plan millions).
MAX_TASKS = 100_000
#: The one-line error without the extra installed (``{command}``: batch, bench).
DASK_MISSING = "the {command} command needs Dask: pip install mitsuba-mrt[batch]"
#: How often a task is resubmitted after the cluster cancelled it (a restart).
RESUBMITS = 2
#: Frame time of the animations, milliseconds.
FRAME_MS = 100
#: The table's columns before and after the varying parameters.
LEAD_COLUMNS = ("task", "scene")
ROW_COLUMNS = ("status", "message", "mode_used", "traced_pixels", "pixels", "time_s",
               "reference_time_s", "relative_time", "error", "psnr_db", "task_time_s",
               "worker")


# -- values and combinations ---------------------------------------------------------


def _number(text: str) -> int | float | None:
    try:
        return int(text)
    except ValueError:
        pass
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def _format(value: float) -> str:
    text = f"{value:.12g}"
    return "0" if text == "-0" else text


def _range(text: str, where: str) -> list[str]:
    parts = text.split(":")
    if len(parts) not in (2, 3):
        raise MRTError(f"{where}: a range is start:stop:step, got {text!r}")
    numbers = [_number(p.strip()) for p in parts]
    if any(n is None for n in numbers):
        raise MRTError(f"{where}: a range start:stop:step needs numbers, got {text!r}")
    start, stop, step = numbers if len(numbers) == 3 else (*numbers, 1)
    if step == 0:
        raise MRTError(f"{where}: the step of a range cannot be 0")
    if all(isinstance(n, int) for n in (start, stop, step)):
        count = len(range(start, stop, step))
        values = [str(v) for v in itertools.islice(range(start, stop, step), MAX_TASKS + 1)]
    else:
        # stop is exclusive, as in range(); a stop that rounding puts a hair
        # above the last value is not a value
        q = (stop - start) / step
        count = max(0, math.ceil(q - 1e-9 * max(1.0, abs(q))))
        values = [_format(start + i * step) for i in range(min(count, MAX_TASKS + 1))]
    if count == 0:
        raise MRTError(f"{where}: the range {text} is empty (stop is exclusive)")
    if count > MAX_TASKS:
        raise MRTError(f"{where}: the range {text} has {count} values, more than {MAX_TASKS}")
    return values


def parse_values(text: str, name: str = "value") -> list[str]:
    """The values of one ``-D name=VALUES``, as the strings Mitsuba is given.

    ``VALUES`` is one value, a comma list, or a range ``start:stop:step``
    (stop exclusive, as Python's ``range``; ``start:stop`` steps by 1;
    floats allowed); a comma list may hold ranges.  Bad input raises a
    one-line :class:`MRTError` naming the define.

    Examples
    --------
    >>> parse_values("16")
    ['16']
    >>> parse_values("path,matte")
    ['path', 'matte']
    >>> parse_values("0:360:90")
    ['0', '90', '180', '270']
    >>> parse_values("0:1:0.25")
    ['0', '0.25', '0.5', '0.75']
    >>> parse_values("0:0.3:0.1")
    ['0', '0.1', '0.2']
    >>> parse_values("0:60:30,90")
    ['0', '30', '90']
    """
    where = f"-D {name}={text}"
    items = text.split(",") if "," in text else [text]
    values: list[str] = []
    for item in items:
        item = item.strip()
        if not item and len(items) > 1:
            raise MRTError(f"{where}: empty value in a comma list")
        values += _range(item, where) if ":" in item else [item]
    twice = sorted({v for v in values if values.count(v) > 1})
    if twice:
        raise MRTError(f"{where}: the value {twice[0]!r} is given twice")
    return values


@dataclass(frozen=True)
class Sweep:
    """The ``-D`` options of a batch: each name with its values, in order.

    Examples
    --------
    >>> s = Sweep.parse([("res", "16"), ("azimuth", "0:90:30"), ("spp", "1,4")])
    >>> s.varying
    ('azimuth', 'spp')
    >>> len(s.combinations()), s.combinations()[1]
    (6, {'res': '16', 'azimuth': '0', 'spp': '4'})
    """

    names: tuple[str, ...] = ()
    values: tuple[tuple[str, ...], ...] = ()

    @classmethod
    def parse(cls, defines) -> "Sweep":
        """From ``(name, VALUES)`` pairs (the command line's ``-D``)."""
        names, values = [], []
        for name, text in defines:
            if name in names:
                raise MRTError(f"-D {name} is given twice; put its values in one comma list")
            names.append(name)
            values.append(tuple(parse_values(text, name)))
        sweep = cls(tuple(names), tuple(values))
        count = math.prod(len(v) for v in sweep.values)
        if count > MAX_TASKS:
            raise MRTError(f"the -D values make {count} combinations, more than {MAX_TASKS}")
        return sweep

    @property
    def varying(self) -> tuple[str, ...]:
        """The names given more than one value: they name the task folders."""
        return tuple(n for n, v in zip(self.names, self.values) if len(v) > 1)

    def combinations(self) -> list[dict[str, str]]:
        """Every combination (the cartesian product, the first ``-D`` outermost)."""
        return [dict(zip(self.names, combo)) for combo in itertools.product(*self.values)]


# -- tasks -----------------------------------------------------------------------------


def _safe(text: str) -> str:
    """``text`` fit for a folder name (path separators and odd characters -> '_')."""
    return re.sub(r"[^A-Za-z0-9._+=-]", "_", text) or "_"


def task_name(stem: str, combo: dict[str, str], varying) -> str:
    """The folder of one task: ``stem`` then ``_name=value`` per varying parameter.

    >>> task_name("orbit", {"res": "16", "azimuth": "30"}, ["azimuth"])
    'orbit_azimuth=30'
    >>> task_name("fig1", {"res": "16"}, [])
    'fig1'
    """
    return _safe(stem) + "".join(f"_{_safe(n)}={_safe(combo[n])}" for n in varying)


@dataclass(frozen=True)
class BatchTask:
    """One render of a batch: what ``run_render_job`` is given, and its folder."""

    name: str                     # the folder, unique in the batch
    scene: str                    # absolute path, read by the worker
    defines: dict                 # every -D, as Mitsuba's strings
    varying: dict                 # the varying ones, the table's columns
    job: dict = field(default_factory=dict)  # RenderJob's other fields

    @property
    def stem(self) -> str:
        return Path(self.scene).stem


#: RenderJob's fields that a batch passes through unchanged.
JOB_FIELDS = ("param_overrides", "spp", "seed", "variant", "reference", "mode")


def check_job_options(options: dict) -> dict:
    """Validate the render options once, before any task (one-line MRTError)."""
    from ..modes import check_mode
    from ..renderer.variants import VARIANT_CHOICES
    from ..types import MRTParams

    unknown = set(options) - set(JOB_FIELDS)
    if unknown:
        raise MRTError(f"unknown render options: {', '.join(sorted(unknown))}")
    MRTParams(**options.get("param_overrides", {}))
    if options.get("mode") is not None:
        check_mode(options["mode"], ("auto",))
    if options.get("spp") is not None and int(options["spp"]) < 1:
        raise MRTError(f"spp must be >= 1, got {options['spp']}")
    variant = options.get("variant", "auto")
    if variant not in VARIANT_CHOICES:
        raise MRTError(f"unknown variant {variant!r}; choose one of {', '.join(VARIANT_CHOICES)}")
    return dict(options)


def plan_tasks(scenes, sweep: Sweep, job_options: dict | None = None) -> list[BatchTask]:
    """One task per (scene, combination), scenes outermost, in the order given."""
    job = check_job_options(job_options or {})
    scenes = [os.path.abspath(os.fspath(s)) for s in scenes]
    if not scenes:
        raise MRTError("no scene given")
    stems: dict[str, str] = {}
    for scene in scenes:
        stem = Path(scene).stem
        if stems.setdefault(stem, scene) != scene:
            raise MRTError(f"two scenes named {stem}: {stems[stem]} and {scene}; "
                           "their outputs would share folders")
    if len(stems) < len(scenes):
        raise MRTError("a scene is given twice")
    combos = sweep.combinations()
    if len(scenes) * len(combos) > MAX_TASKS:
        raise MRTError(f"{len(scenes) * len(combos)} tasks, more than {MAX_TASKS}")
    tasks, names = [], {}
    for scene in scenes:
        for combo in combos:
            varying = {n: combo[n] for n in sweep.varying}
            name = task_name(Path(scene).stem, combo, sweep.varying)
            if name in names:
                raise MRTError(f"-D values {names[name]} and {varying} give the same "
                               f"folder name {name}")
            names[name] = varying
            tasks.append(BatchTask(name, scene, dict(combo), varying, dict(job)))
    return tasks


# -- the worker side ---------------------------------------------------------------------


def _base_row(task: BatchTask) -> dict:
    row = {"task": task.name, "scene": task.scene, **task.varying}
    row.update({c: None for c in ROW_COLUMNS})
    return row


def summary_row(task: BatchTask, summary: dict, status: str) -> dict:
    """The table row of a task from its summary (``RunSummary.as_dict()``)."""
    row = _base_row(task)
    row.update(status=status, message="", mode_used=summary["mode_used"],
               traced_pixels=sum(summary["traced"].values()),
               pixels=summary["width"] * summary["height"],
               time_s=summary["timings"]["total"],
               reference_time_s=summary["reference_time_s"],
               relative_time=summary["relative_time"], error=summary["error"],
               psnr_db=summary["psnr_db"])
    return row


def failed_row(task: BatchTask, message: str) -> dict:
    """The table row of a task that failed with ``message`` (one line)."""
    row = _base_row(task)
    row.update(status="failed", message=message)
    return row


def _remove_leftovers(folder: Path, stem: str) -> None:
    """Temporary files of this task's outputs, left by a worker that died writing them.

    The folder is this task's alone; the atomic writers' temporary files are
    hidden (``.<name>.<random>``, ``..<name>.<random>`` when nested).
    """
    for path in folder.glob(".*"):
        if path.name.lstrip(".").startswith(stem):
            try:
                path.unlink()
            except OSError:
                pass


def _set_jit_threads(jit_threads) -> None:
    """Dr.Jit's thread count for this worker: an int, or per worker address."""
    if isinstance(jit_threads, dict):
        try:
            from distributed import get_worker

            jit_threads = jit_threads.get(get_worker().address)
        except (ImportError, ValueError):
            jit_threads = None
    if jit_threads:
        import drjit as dr

        if dr.thread_count() != jit_threads:
            dr.set_thread_count(int(jit_threads))


def run_task(task: BatchTask, out_dir: str, jit_threads=None) -> dict:
    """Run one task where it is called (a Dask worker): render, write, return its row.

    Sets Dr.Jit's thread count (``jit_threads``: a count, or a dict from
    worker address to a count) and calls :func:`run_render_job` exactly as
    ``render`` does; it activates the task's variant in this process.
    An exception becomes a failed row with its one-line message;
    ``task_time_s`` is the task's whole wall time here.
    """
    start = time.perf_counter()
    try:
        from ..runtime import configure
        from .job import RenderJob, run_render_job

        configure()
        _set_jit_threads(jit_threads)
        folder = Path(out_dir) / task.name
        if folder.is_dir():
            _remove_leftovers(folder, task.stem)
        summary = run_render_job(RenderJob(scene=task.scene, out_dir=os.fspath(folder),
                                           defines=dict(task.defines), **task.job))
        row = summary_row(task, summary.as_dict(), "ok")
    except Exception as exc:  # noqa: BLE001 - a failed task is a row, the batch goes on
        row = failed_row(task, one_line(exc))
    row["task_time_s"] = time.perf_counter() - start
    row["worker"] = f"{socket.gethostname()}:{os.getpid()}"
    return row


# -- resuming ------------------------------------------------------------------------------


def _matches(task: BatchTask, summary: dict) -> bool:
    """Whether a finished render's summary is the one ``task`` asks for."""
    job = task.job
    if summary.get("scene") != task.scene or summary.get("defines") != task.defines:
        return False
    if summary.get("seed") != job.get("seed", 0):
        return False
    for key in ("spp", "mode"):
        if job.get(key) is not None and summary.get(key) != job[key]:
            return False
    if job.get("variant", "auto") != "auto" and summary.get("variant") != job["variant"]:
        return False
    params = summary.get("params", {})
    if any(params.get(k) != v for k, v in job.get("param_overrides", {}).items()):
        return False
    has_reference = f"{task.stem}_ref.exr" in summary.get("outputs", [])
    wants_reference = job.get("reference", True) and summary.get("mode_used") != "full"
    return has_reference == wants_reference


def completed_row(task: BatchTask, out_dir) -> dict | None:
    """The row of a task whose outputs are complete and match it, else None.

    Its JSON is written last, in the same atomic set as its images, so its
    presence means the whole set is there.
    """
    path = Path(out_dir) / task.name / f"{task.stem}.json"
    try:
        summary = json.loads(path.read_text())
        if not _matches(task, summary):
            return None
        return summary_row(task, summary, "skipped")
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None


# -- the table and the animations -------------------------------------------------------


def table_columns(tasks) -> list[str]:
    """The table's columns: task, scene, the varying parameters, the results."""
    varying = list(dict.fromkeys(n for t in tasks for n in t.varying))
    return [*LEAD_COLUMNS, *varying, *ROW_COLUMNS]


def write_table(path, rows, columns) -> None:
    """Write the batch table as CSV (None as an empty cell), atomically."""
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(columns), extrasaction="ignore")
            writer.writeheader()
            for row in rows:
                writer.writerow({k: "" if v is None else v for k, v in row.items()})


def read_table(path) -> list[dict]:
    """The batch table's rows, as strings."""
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def write_animation(path, frames, frame_ms: int = FRAME_MS) -> None:
    """Write PNG ``frames`` (paths, in order) as a looping GIF, atomically.

    Frames of different sizes (the parameter is the resolution) raise MRTError.
    """
    import imageio.v3 as iio
    import numpy as np

    images = [np.asarray(iio.imread(p))[..., :3] for p in frames]
    if len({image.shape for image in images}) > 1:
        raise MRTError(f"no animation {Path(path).name}: its frames differ in size")
    with atomic_path(path) as tmp:
        iio.imwrite(tmp, np.stack(images), extension=".gif", duration=frame_ms, loop=0)


def animations(tasks, rows: dict, out_dir) -> tuple[dict[str, list[Path]], list[str]]:
    """The frames of each scene's animation (exactly one varying parameter), and notes.

    Frames are the tasks' ``_mrt.png`` in parameter order; failed tasks have
    none; a scene with fewer than two frames gets no animation and a note.
    """
    varying = {n for t in tasks for n in t.varying}
    if len(varying) != 1:
        return {}, []
    frames: dict[str, list[Path]] = {}
    for task in tasks:
        png = Path(out_dir) / task.name / f"{task.stem}_mrt.png"
        frames.setdefault(task.stem, [])
        if rows.get(task.name, {}).get("status") in ("ok", "skipped") and png.exists():
            frames[task.stem].append(png)
    out, notes = {}, []
    for stem, pngs in frames.items():
        if len(pngs) < 2:
            notes.append(f"no animation {stem}.gif: fewer than 2 frames")
        else:
            out[stem] = pngs
    return out, notes


# -- the driver -----------------------------------------------------------------------------


@dataclass
class BatchResult:
    """What a batch did: the rows (task order), the table, the animations."""

    rows: list[dict]
    table: Path
    animations: list[Path]
    notes: list[str]

    def count(self, status: str) -> int:
        return sum(r["status"] == status for r in self.rows)

    @property
    def failed(self) -> int:
        return self.count("failed")


def _require_dask(command: str = "batch"):
    try:
        import distributed
    except ImportError:
        raise MRTError(DASK_MISSING.format(command=command)) from None
    return distributed


def check_cluster_options(scheduler: str | None, workers: int | None,
                          command: str = "batch") -> None:
    """Dask is installed, and ``--scheduler``/``--workers`` make sense (one-line MRTError)."""
    _require_dask(command)
    if workers is not None and workers < 1:
        raise MRTError(f"--workers must be >= 1, got {workers}")
    if workers is not None and scheduler:
        raise MRTError("--workers sizes the local cluster; with --scheduler the "
                       "cluster's own workers run the tasks")


def _cores() -> int:
    return os.cpu_count() or 1


@contextmanager
def _client(scheduler: str | None, workers: int | None, echo):
    """A Dask client: on the cluster at ``scheduler``, or on a new LocalCluster.

    Yields ``(client, jit_threads)`` with ``jit_threads`` what :func:`run_task`
    sets Dr.Jit's thread count to.  The client is not made the process's
    default: a caller's own client stays its default.
    """
    import logging

    from distributed import Client, LocalCluster

    if scheduler:
        try:
            client = Client(scheduler, timeout="20s", set_as_default=False)
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
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                           dashboard_address="127.0.0.1:0", silence_logs=logging.ERROR)
    try:
        client = Client(cluster, set_as_default=False)
        try:
            echo(f"dask: local cluster of {n} worker processes x 1 thread, Dr.Jit "
                 f"{jit_threads} thread{'s' if jit_threads > 1 else ''} each "
                 f"({_cores()} cores // {n} workers)" + _dashboard(client))
            yield client, jit_threads
        finally:
            client.close()
    finally:
        cluster.close()


def _dashboard(client) -> str:
    import importlib.util

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


def run_batch(scenes, out_dir, defines=(), *, scheduler: str | None = None,
              workers: int | None = None, progress: bool = True, echo=print,
              **job_options) -> BatchResult:
    """Render every (scene, combination of ``defines``) on a Dask cluster.

    Parameters
    ----------
    scenes : paths of scene files (read by the workers, by absolute path)
    out_dir : the batch's folder: a folder per task, ``batch.csv``, GIFs
    defines : ``(name, VALUES)`` pairs, see :func:`parse_values`
    scheduler : address of a running Dask scheduler (``tcp://host:8786``);
        default: a LocalCluster of ``workers`` processes (default: one per
        core), one thread each, Dr.Jit's threads split between them
    progress : a progress bar over the tasks on stderr
    echo : where the lines about the cluster and the outputs go
    **job_options : :class:`RenderJob` fields ``param_overrides``, ``spp``,
        ``seed``, ``variant``, ``reference``, ``mode``

    Tasks whose outputs are complete are skipped (status ``skipped``, the
    row read back from their JSON); a failed task is a row with status
    ``failed`` and its message, and the batch goes on.  Ctrl-C cancels the
    tasks not yet done and still writes the table (status ``pending`` for
    those).
    """
    check_cluster_options(scheduler, workers)
    tasks = plan_tasks(scenes, Sweep.parse(defines), job_options)
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise MRTError(f"cannot create output folder {out}: {exc.strerror or exc}") from None
    out = out.resolve()
    rows: dict[str, dict] = {}
    for task in tasks:
        row = completed_row(task, out)
        if row is not None:
            rows[task.name] = row
    todo = [t for t in tasks if t.name not in rows]
    echo(f"batch: {len(tasks)} task{'s' if len(tasks) > 1 else ''} into {out}"
         + (f", {len(tasks) - len(todo)} already complete (skipped)" if len(todo) < len(tasks)
            else ""))
    columns = table_columns(tasks)
    table = out / TABLE_NAME
    try:
        if todo:
            _run_on_cluster(todo, out, rows, scheduler, workers, progress, echo)
    finally:
        ordered = [rows.get(t.name) or {**_base_row(t), "status": "pending"} for t in tasks]
        write_table(table, ordered, columns)
    frames, notes = animations(tasks, rows, out)
    gifs = []
    if frames:
        try:
            import imageio  # noqa: F401
        except ImportError:
            notes.append("no animation: pip install imageio (the batch extra)")
            frames = {}
    for stem, pngs in frames.items():
        try:
            write_animation(out / f"{stem}.gif", pngs)
            gifs.append(out / f"{stem}.gif")
        except MRTError as exc:
            notes.append(str(exc))
    return BatchResult(ordered, table, gifs, notes)


def _run_on_cluster(todo, out: Path, rows: dict, scheduler, workers, progress, echo) -> None:
    from distributed import as_completed
    from tqdm import tqdm

    with _client(scheduler, workers, echo) as (client, jit_threads):
        def submit(task):
            return client.submit(run_task, task, os.fspath(out), jit_threads,
                                 key=f"render-{task.name}-{uuid.uuid4().hex[:8]}",
                                 retries=2, pure=False)

        futures = {submit(task): task for task in todo}
        resubmits = {task.name: 0 for task in todo}
        # this client's loop, not the process's default client's (a user's own)
        pending = as_completed(list(futures), loop=client.loop)
        bar = tqdm(total=len(todo), unit="task", desc="batch", disable=not progress,
                   file=sys.stderr, dynamic_ncols=True)
        try:
            for future in pending:
                task = futures.pop(future)
                if future.status == "cancelled" and resubmits[task.name] < RESUBMITS:
                    # the cluster forgot it (a restart): run it again
                    resubmits[task.name] += 1
                    again = submit(task)
                    futures[again] = task
                    pending.add(again)
                    continue
                try:
                    row = future.result()
                except Exception as exc:  # noqa: BLE001 - retries spent, or KilledWorker
                    row = failed_row(task, one_line(exc))
                rows[task.name] = row
                bar.update(1)
                if row["status"] == "failed":
                    bar.write(f"failed: {task.name}: {row['message']}", file=sys.stderr)
        finally:
            bar.close()
            if futures:
                client.cancel(list(futures))


# -- other commands' tasks on the same cluster ----------------------------------------------


def _call_on_worker(fn, args: tuple, jit_threads):
    """``fn(*args)`` on a worker, in a process tuned and with Dr.Jit's threads set as
    :func:`run_task` does; ``fn`` activates its own variant."""
    from ..runtime import configure

    configure()
    _set_jit_threads(jit_threads)
    return fn(*args)


@contextmanager
def cluster_map(scheduler: str | None = None, workers: int | None = None, echo=print,
                command: str = "bench"):
    """A Dask cluster for another command's tasks (``bench``: one per point).

    The cluster is that of :func:`run_batch` (``scheduler``, or a LocalCluster
    of ``workers`` processes); yields ``map_calls(fn, calls)``, which submits
    ``fn(*call)`` for every tuple of ``calls`` (``fn`` importable on the
    workers) and yields ``(index, result)`` as each finishes.  A call that
    raises, once its retries are spent, raises here; the others are cancelled.
    """
    check_cluster_options(scheduler, workers, command)

    def map_calls(fn, calls):
        from distributed import as_completed

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

    with _client(scheduler, workers, echo) as (client, jit_threads):
        yield map_calls

"""The tasks of a batch: planning them, running one on a worker, resuming.

:func:`plan_tasks` makes one :class:`BatchTask` per (scene, combination of
the ``-D`` values), validating everything once before any task;
:func:`run_task` is what a worker runs: :func:`mitsuba_mrt.app.job.run_render_job`
into the task's folder, returning its row of the batch table (a failure is
a row too); :func:`completed_row` is the row of a task that an earlier run
finished, which a rerun skips.
"""

from __future__ import annotations

import json
import os
import re
import socket
import time
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import MRTError, one_line
from ..modes import check_mode, render_modes
from ..renderer.variants import VARIANT_CHOICES
from ..runtime import configure
from ..types import MRTParams, check_seed, check_spp, is_integer
from .cluster import set_jit_threads
from .job import RenderJob, output_stem, run_render_job
from .sweep import MAX_TASKS, Sweep

#: The table's columns before and after the varying parameters.
LEAD_COLUMNS = ("task", "scene")
ROW_COLUMNS = ("status", "message", "mode_used", "traced_pixels", "pixels", "time_s",
               "reference_time_s", "relative_time", "error", "psnr_db", "task_time_s",
               "worker")


# -- planning ------------------------------------------------------------------------------


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
        """Its outputs' name (:func:`~mitsuba_mrt.app.job.output_stem`)."""
        return output_stem(self.scene, self.job.get("sensor", 0))


#: RenderJob's fields that a batch passes through unchanged.
JOB_FIELDS = ("param_overrides", "spp", "seed", "variant", "reference", "mode", "sensor")


def check_job_options(options: dict) -> dict:
    """Validate the render options once, before any task (one-line MRTError)."""
    unknown = set(options) - set(JOB_FIELDS)
    if unknown:
        raise MRTError(f"unknown render options: {', '.join(sorted(unknown))}")
    MRTParams(**options.get("param_overrides", {}))
    if options.get("mode") is not None:
        check_mode(options["mode"], render_modes())
    if options.get("spp") is not None:
        check_spp(options["spp"])
    check_seed(options.get("seed", 0))
    sensor = options.get("sensor", 0)
    if not is_integer(sensor) or sensor < 0:
        raise MRTError(f"sensor must be an index >= 0, got {sensor!r}")
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


def pending_row(task: BatchTask) -> dict:
    """The table row of a task not done when the batch stopped (Ctrl-C)."""
    return {**_base_row(task), "status": "pending"}


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
        configure()
        set_jit_threads(jit_threads)
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
    if any(summary.get(key, 0) != job.get(key, 0) for key in ("seed", "sensor")):
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


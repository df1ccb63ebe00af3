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

This module is the driver, :func:`run_batch`; the pieces need no Dask:

- :mod:`.sweep`: the ``-D`` value syntax (:func:`~.sweep.parse_values`) and
  the combinations (:class:`~.sweep.Sweep`);
- :mod:`.tasks`: the tasks (:func:`~.tasks.plan_tasks`), the worker's task
  (:func:`~.tasks.run_task`) and resuming (:func:`~.tasks.completed_row`);
- :mod:`.outputs`: the table (:func:`~.outputs.write_table`) and the GIFs;
- :mod:`.cluster`: the Dask client (``dask.distributed``, the ``batch``
  extra, imported there on first use) and :func:`~.cluster.cluster_map`,
  which lends the same cluster to another command's tasks:
  ``bench --workers/--scheduler`` measures its points on it.
"""

from __future__ import annotations

import os
import sys
import uuid
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from ..errors import MRTError, one_line
from .cluster import check_cluster_options, cluster_client, require_distributed
from .outputs import animations, table_columns, write_animations, write_table
from .sweep import Sweep
from .tasks import completed_row, failed_row, pending_row, plan_tasks, run_task

#: The batch table, in the output folder.
TABLE_NAME = "batch.csv"
#: How often a task is resubmitted after the cluster cancelled it (a restart).
RESUBMITS = 2


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


def run_batch(scenes, out_dir, defines=(), *, scheduler: str | None = None,
              workers: int | None = None, progress: bool = True, echo=print,
              **job_options) -> BatchResult:
    """Render every (scene, combination of ``defines``) on a Dask cluster.

    Parameters
    ----------
    scenes : paths of scene files (read by the workers, by absolute path)
    out_dir : the batch's folder: a folder per task, ``batch.csv``, GIFs
    defines : ``(name, VALUES)`` pairs, see :func:`.sweep.parse_values`
    scheduler : address of a running Dask scheduler (``tcp://host:8786``);
        default: a LocalCluster of ``workers`` processes (default: one per
        core), one thread each, Dr.Jit's threads split between them
    progress : a progress bar over the tasks on stderr
    echo : where the lines about the cluster and the outputs go
    **job_options : :class:`RenderJob` fields ``param_overrides``, ``spp``,
        ``seed``, ``variant``, ``reference``, ``mode``, ``sensor``

    Tasks whose outputs are complete are skipped (status ``skipped``, the
    row read back from their JSON); a failed task is a row with status
    ``failed`` and its message, and the batch goes on.  Ctrl-C cancels the
    tasks not yet done and still writes the table (status ``pending`` for
    those).  Where the cluster cannot be reached nothing is written (the
    folder, where this call made it, is removed again).
    """
    check_cluster_options(scheduler, workers)
    tasks = plan_tasks(scenes, Sweep.parse(defines), job_options)
    out = Path(out_dir)
    created = not out.exists()
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
    reached: list = []  # (non-empty once the cluster is: a table is then written, whatever follows)
    try:
        if todo:
            _run_on_cluster(todo, out, rows, scheduler, workers, progress, echo, reached)
    finally:
        ordered = [rows.get(t.name) or pending_row(t) for t in tasks]
        if reached or not todo:
            write_table(table, ordered, columns)
        elif created and not any(out.iterdir()):  # no cluster, nothing rendered: no folder
            out.rmdir()
    frames, notes = animations(tasks, rows, out)
    gifs, unwritten = write_animations(frames, out)
    return BatchResult(ordered, table, gifs, notes + unwritten)


def _run_on_cluster(todo, out: Path, rows: dict, scheduler, workers, progress, echo,
                    reached: list) -> None:
    """Run ``todo`` on the cluster, each finished task's row into ``rows``
    (``reached`` gets an item once the cluster is connected)."""
    as_completed = require_distributed().as_completed
    with cluster_client(scheduler, workers, echo) as (client, jit_threads):
        reached.append(True)
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



"""The batch's own outputs: the table ``batch.csv`` and the scenes' animations.

The table has a row per task (:data:`~.tasks.LEAD_COLUMNS`, the varying
parameters, :data:`~.tasks.ROW_COLUMNS`); with exactly one varying
parameter each scene's frames become a looping GIF (``imageio``, the
``batch`` extra, imported on first use).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ..errors import MRTError
from ..imageio import atomic_path
from .tasks import LEAD_COLUMNS, ROW_COLUMNS

#: Frame time of the animations, milliseconds.
FRAME_MS = 100
#: The note of a batch whose animations need imageio.
NO_IMAGEIO = "no animation: pip install imageio (the batch extra)"


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
    iio = _imageio()
    if iio is None:
        raise MRTError(NO_IMAGEIO)
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



def write_animations(frames: dict, out_dir) -> tuple[list[Path], list[str]]:
    """Write each scene's frames (:func:`animations`) as ``<out_dir>/<scene>.gif``.

    Returns the GIFs written and a note per one not written (one note in
    all without imageio).
    """
    if frames and _imageio() is None:
        return [], [NO_IMAGEIO]
    gifs, notes = [], []
    for stem, pngs in frames.items():
        try:
            write_animation(Path(out_dir) / f"{stem}.gif", pngs)
            gifs.append(Path(out_dir) / f"{stem}.gif")
        except MRTError as exc:
            notes.append(str(exc))
    return gifs, notes


def _imageio():
    """imageio's v3 API (the ``batch`` extra), imported on first use; None without it."""
    try:
        import imageio.v3 as iio
    except ImportError:
        return None
    return iio

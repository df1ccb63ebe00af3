"""What earlier processes measured, kept on disk beside Dr.Jit's kernel cache.

A time limit is planned from what a render's launches cost.  A process
learns that from its own launches, and a user's fresh process has none: it
spends part of its limit measuring (a probe, a first launch of few samples)
what the last process that rendered the scene already knew.  This module
keeps such measures across processes, per scene (a digest of what is traced
and the image's pixel count), in one JSON file in Dr.Jit's kernel cache
folder (``~/.drjit``): the kernels those launches compiled are there too,
and clearing the folder forgets both.  Nothing is read or written on import.

``MITSUBA_MRT_MEMORY=off`` switches it off (the test suite does; so do
``0``, ``false`` and ``no``); ``MITSUBA_MRT_MEMORY=PATH`` keeps the file at ``PATH``.  A file that cannot
be read or written is as no file: the render plans from its own measures.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

#: The file's name in Dr.Jit's kernel cache folder.
FILE_NAME = "mitsuba-mrt-memory.json"
#: Scenes the file keeps (the most recently remembered).
KEPT_SCENES = 64
#: The file's format; a file of another is ignored, and replaced when written.
VERSION = 1
#: ``MITSUBA_MRT_MEMORY`` values that switch the memory off (any case): a
#: user who writes ``0`` means off, not a file named 0 in the working folder.
OFF = ("off", "0", "false", "no")


def path() -> Path | None:
    """The memory's file (:func:`file_for` ``MITSUBA_MRT_MEMORY``), or None where it is off."""
    return file_for(os.environ.get("MITSUBA_MRT_MEMORY", ""))


def enabled() -> bool:
    """Whether renders remember and recall (``MITSUBA_MRT_MEMORY`` is not ``off``)."""
    return path() is not None


def file_for(setting: str) -> Path | None:
    """The file a ``MITSUBA_MRT_MEMORY`` value names: none for :data:`OFF`'s,
    the file in Dr.Jit's kernel cache folder for an empty value.

    Examples
    --------
    >>> file_for("off") is None, file_for("0") is None, str(file_for("/tmp/m.json"))
    (True, True, '/tmp/m.json')
    >>> file_for("").name
    'mitsuba-mrt-memory.json'
    """
    if setting.strip().lower() in OFF:
        return None
    return Path(setting) if setting else Path.home() / ".drjit" / FILE_NAME


def _read(file: Path) -> dict:
    """The file's scenes, {} where it is missing, unreadable or of another format."""
    try:
        with open(file, encoding="utf-8") as f:
            data = json.load(f)
    except (OSError, ValueError):
        return {}
    if not isinstance(data, dict) or data.get("version") != VERSION:
        return {}
    scenes = data.get("scenes")
    return scenes if isinstance(scenes, dict) else {}


def recall(key: str) -> dict | None:
    """What was remembered for ``key`` (:func:`remember`), else None."""
    file = path()
    value = None if file is None else _read(file).get(key)
    return value if isinstance(value, dict) else None


def remember(key: str, value: dict) -> None:
    """Keep ``value`` (JSON-serialisable) for ``key``, the most recent of the
    file's last :data:`KEPT_SCENES`; the file is replaced whole (a reader
    sees the old one or the new one), and nothing happens where it cannot be."""
    file = path()
    if file is None:
        return
    scenes = _read(file)
    scenes.pop(key, None)
    scenes[key] = value
    for old in list(scenes)[:-KEPT_SCENES]:
        del scenes[old]
    try:
        file.parent.mkdir(parents=True, exist_ok=True)
        handle, temporary = tempfile.mkstemp(dir=file.parent, prefix=".mitsuba-mrt-")
        try:
            text = json.dumps({"version": VERSION, "scenes": scenes})  # (C encoder; not dump)
            with os.fdopen(handle, "w", encoding="utf-8") as f:
                f.write(text)
            os.replace(temporary, file)
        except BaseException:
            os.unlink(temporary)
            raise
    except OSError:
        return

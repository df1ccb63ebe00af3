"""Writing results: multi-channel EXR (OpenEXR), PNG and JSON, all atomically.

Every writer writes to a temporary file in the target folder and renames it
into place, so a failure never leaves a half-written output; an
:class:`OutputSet` does the same for several files together.

It imports nothing else of the package but :mod:`.errors`, so that both
:mod:`.app` and :mod:`.bench` may import it and :mod:`.bench` imports
nothing of :mod:`.app`.
"""

from __future__ import annotations

import json
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from .errors import MRTError


@contextmanager
def atomic_path(path: str | os.PathLike):
    """Yield a temporary path beside ``path``; rename it to ``path`` on success."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    try:
        yield tmp
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_exr(path: str | os.PathLike, channels: dict[str, np.ndarray]) -> None:
    """Write named (height, width) channels into one EXR file.

    Float channels are stored as 32-bit float, integer channels as 32-bit
    unsigned int (ids keep every bit).

    Examples
    --------
    >>> import tempfile, os
    >>> p = os.path.join(tempfile.mkdtemp(), "a.exr")
    >>> write_exr(p, {"R": np.zeros((2, 2)), "id": np.ones((2, 2), dtype=np.uint32)})
    >>> os.path.exists(p)
    True
    """
    import OpenEXR

    data = {}
    for name, arr in channels.items():
        arr = np.asarray(arr)
        if arr.ndim != 2:
            raise MRTError(f"EXR channel {name!r} must be 2-D, got shape {arr.shape}")
        if np.issubdtype(arr.dtype, np.integer) or arr.dtype == bool:
            data[name] = np.ascontiguousarray(arr, dtype=np.uint32)
        else:
            data[name] = np.ascontiguousarray(arr, dtype=np.float32)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with atomic_path(path) as tmp:
        with OpenEXR.File(header, data) as f:
            f.write(tmp)


def read_exr(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read every channel of an EXR file into a dict of (height, width) arrays."""
    import OpenEXR

    with OpenEXR.File(str(path), separate_channels=True) as f:
        return {name: np.array(ch.pixels) for name, ch in f.channels().items()}


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """Linear RGB in [0, 1] to 8-bit sRGB."""
    x = np.clip(np.nan_to_num(np.asarray(linear, dtype=np.float64)), 0.0, 1.0)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.round(srgb * 255.0).astype(np.uint8)


def write_png(path: str | os.PathLike, rgb_linear: np.ndarray) -> None:
    """Write a linear (height, width, 3) image as an sRGB PNG."""
    from matplotlib.image import imsave

    with atomic_path(path) as tmp:
        imsave(tmp, srgb_encode(rgb_linear), format="png")


def write_error_png(path: str | os.PathLike, errors: np.ndarray,
                    floor: float = 1e-4, cmap: str = "inferno",
                    label: str = "per-pixel error") -> None:
    """Write an error map, log colour scale from ``floor`` to 1, with a colour bar."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.colors import LogNorm
    from matplotlib.figure import Figure

    errors = np.clip(np.nan_to_num(np.asarray(errors, dtype=np.float64)), floor, 1.0)
    height, width = errors.shape
    dpi = 100
    fig = Figure(figsize=((width + 110) / dpi, max(height, 160) / dpi), dpi=dpi)
    FigureCanvasAgg(fig)
    ax = fig.add_axes([0.0, 0.0, width / (width + 110), 1.0])
    shown = ax.imshow(errors, cmap=cmap, norm=LogNorm(vmin=floor, vmax=1.0),
                      interpolation="nearest")
    ax.set_axis_off()
    bar = fig.add_axes([width / (width + 110) + 0.02, 0.08, 12 / (width + 110), 0.84])
    fig.colorbar(shown, cax=bar).set_label(label, fontsize=8)
    bar.tick_params(labelsize=7)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi)


def write_json(path: str | os.PathLike, obj) -> None:
    """Write ``obj`` as indented JSON."""
    text = json.dumps(obj, indent=2, sort_keys=False, allow_nan=True)
    with atomic_path(path) as tmp:
        Path(tmp).write_text(text + "\n")


class OutputSet:
    """Several output files that appear together or not at all.

    Each writer is given :meth:`path` (a temporary file beside the final
    one); when the ``with`` block ends without an error every file is
    renamed into place, in the order asked for; after an error (or Ctrl-C)
    every temporary file is removed and no final file is touched.

    Examples
    --------
    >>> import tempfile
    >>> folder = Path(tempfile.mkdtemp())
    >>> with OutputSet(folder) as out:
    ...     _ = Path(out.path("a.txt")).write_text("a")
    >>> sorted(p.name for p in folder.iterdir())
    ['a.txt']
    """

    def __init__(self, folder: str | os.PathLike):
        self.folder = Path(folder)
        self._files: list[tuple[str, str]] = []  # (temporary, final name)

    def __enter__(self) -> "OutputSet":
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise MRTError(f"cannot create output folder {self.folder}: "
                           f"{exc.strerror or exc}") from None
        return self

    def path(self, name: str) -> str:
        """A temporary path for the output file ``name``."""
        stem, suffix = os.path.splitext(name)
        try:
            fd, tmp = tempfile.mkstemp(prefix=f".{stem}.", suffix=suffix, dir=self.folder)
        except OSError as exc:
            raise MRTError(f"cannot write into {self.folder}: {exc.strerror or exc}") from None
        os.close(fd)
        self._files.append((tmp, name))
        return tmp

    @property
    def names(self) -> list[str]:
        """The final names, in order."""
        return [name for _, name in self._files]

    def __exit__(self, kind, error, trace) -> None:
        if kind is None:
            try:
                self._place_all()
                return
            except OSError as exc:  # e.g. the disk filled up
                error = exc
            except BaseException:  # Ctrl-C while renaming: nothing appears
                self._remove_temporaries()
                raise
        self._remove_temporaries()
        if isinstance(error, OSError):
            errno_text = error.strerror or str(error)
            raise MRTError(f"cannot write into {self.folder}: {errno_text}") from None

    def _remove_temporaries(self) -> None:
        for tmp, _ in self._files:
            try:
                os.unlink(tmp)
            except FileNotFoundError:
                pass

    def _place_all(self) -> None:
        """Rename every temporary file into place, or none: a failure (or an
        interrupt) part way puts back the files the set replaced, and
        removes those it added."""
        umask = os.umask(0)
        os.umask(umask)
        for tmp, _ in self._files:
            os.chmod(tmp, 0o666 & ~umask)
        placed = []  # (final path, the earlier file's backup or None)
        try:
            for tmp, name in self._files:
                final = self.folder / name
                backup = None
                if os.path.lexists(final):  # keep the earlier file until all are in place
                    fd, backup = tempfile.mkstemp(prefix=f".{name}.", suffix=".old",
                                                  dir=self.folder)
                    os.close(fd)
                    try:
                        os.replace(final, backup)
                    except BaseException:
                        os.unlink(backup)
                        raise
                placed.append((final, backup))
                os.replace(tmp, final)
        except BaseException:
            for final, backup in reversed(placed):
                try:
                    if backup is not None:
                        os.replace(backup, final)
                    elif os.path.lexists(final):
                        os.unlink(final)
                except OSError:
                    pass
            raise
        for _, backup in placed:
            if backup is not None:
                try:
                    os.unlink(backup)
                except OSError:
                    pass


def check_output_folder(folder: str | os.PathLike) -> None:
    """MRTError, before any work, if ``folder`` cannot be made or written into.

    Creates nothing: the nearest existing folder on the way must be a
    folder we may write into (a read-only file system says so too).
    """
    path = Path(folder).absolute()
    probe = path
    while not os.path.lexists(probe) and probe != probe.parent:
        probe = probe.parent
    if not probe.is_dir():
        raise MRTError(f"cannot write into {folder}: {probe} is not a folder")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise MRTError(f"cannot write into {folder}: {probe} is not writable")

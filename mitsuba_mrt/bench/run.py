"""Running a bench experiment end to end: measure every point, then write the report.

:func:`run_experiment` builds the experiment (:mod:`.experiments`),
measures its points one after the other (:mod:`.measure`), rewriting the
CSV after every point so that a crash keeps what was measured, and then
writes the plot, the triptych (or, for ``gallery``, a picture per scene;
:mod:`.plots`) and the markdown tables (:mod:`.analysis`) into the output
folder, each file atomically. ``denoise`` points are measured by
:class:`.measure_denoise.DenoiseRunner` into their own CSV columns, plotted
as error against time.

Given ``map_points`` (the ``bench`` command's ``--scheduler``/``--workers``:
:func:`mitsuba_mrt.app.cluster.cluster_map`), the points are measured
elsewhere, one call of :func:`measure_point` each, all methods of a point in
one process as in the serial run; the rows and pictures are written here, in
the points' order, as the serial run writes them.
"""

from __future__ import annotations

import os
import shlex
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from ..errors import MRTError
from ..imageio import atomic_path
from .experiments import (EXPERIMENTS, Experiment, build_experiment, check_repeats,
                          resolve_methods)
from .analysis import CSV_COLUMNS, environment_line, markdown_tables, read_csv, write_csv
from .measure import MIN_TIMED_SECONDS, PointRunner
from .measure_denoise import DenoiseRunner
from .memory import MemoryMeter
from .plots import plot_denoise, plot_sweep, plot_tradeoff, plot_triptych
from .records import CONVERGED_FACTOR, DENOISE_COLUMNS

#: The subfolder of the output folder that keeps converged references.
CACHE_DIR = "cache"


@dataclass
class ExperimentResult:
    """What one experiment wrote: its rows (as the CSV holds them) and files.

    ``png`` is the plot (None for ``gallery``), ``triptych`` the picture of
    the representative setting, ``pictures`` those of every point.
    """

    rows: list
    csv: Path
    png: Path | None
    triptych: Path | None
    md: Path
    seconds: float
    pictures: list = field(default_factory=list)

    @property
    def files(self) -> list:
        return [f for f in (self.csv, self.png, self.md, self.triptych) if f] + self.pictures


def _scenes_dir(scenes_dir=None) -> Path:
    if scenes_dir is not None:
        path = Path(scenes_dir)
    else:
        path = Path(__file__).resolve().parents[2] / "scenes_xml"
    if not (path / "paper_fig1.xml").is_file():
        raise MRTError(f"the report's scenes are not in {path}: pass --scenes DIR "
                       "(the repository's scenes_xml folder)")
    return path


def _progress(total: int, desc: str, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="run", file=sys.stderr, disable=not enabled,
                dynamic_ncols=True, leave=True)


def run_experiment(name: str, out_dir="out/bench", *, quick: bool = False,
                   repeats: int | None = None, variant: str = "auto", methods=None,
                   res: int | None = None, scenes_dir=None, progress: bool = True,
                   command: str | None = None, map_points=None) -> dict:
    """Run experiment ``name`` (or ``all``) and write its outputs into ``out_dir``.

    Parameters
    ----------
    name : str
        One of :data:`EXPERIMENTS`, or ``all``.
    out_dir : path
    quick : bool
        A reduced sweep at low resolution (repeats 1 unless given).
    repeats : int, optional
        Timed runs of every method at every point (default 3, quick 1).
    variant : str
        Mitsuba variant (``auto``: LLVM when usable).
    methods : list or comma-separated str, optional
        Method names (``mrt-paper``, ``nearest``...); default the experiment's
        (every mode but ``auto``; for ``gallery`` every mode and ``bicubic``);
        ``full`` always.
    res : int, optional
        Image side for every experiment but ``pixels``.
    scenes_dir : path, optional
        Folder of the report's scenes (default: the repository's ``scenes_xml``).
    progress : bool
        Show a progress bar on stderr.
    command : str, optional
        The command line written at the top of the markdown table.
    map_points : callable, optional
        ``map_points(fn, calls)`` runs ``fn(*call)`` for every tuple of
        ``calls`` (elsewhere: a Dask cluster) and yields ``(index, result)``
        as each finishes; each point is then one :func:`measure_point` call.
        Default: every point in this process, one after the other.

    Returns
    -------
    dict
        ``experiment -> ExperimentResult`` (for ``all``: one entry per experiment).
    """
    if name == "all":
        out = {}
        for exp in EXPERIMENTS:
            out.update(run_experiment(exp, out_dir, quick=quick, repeats=repeats,
                                      variant=variant, methods=methods,
                                      res=None if exp == "pixels" else res,
                                      scenes_dir=scenes_dir, progress=progress,
                                      command=command, map_points=map_points))
        return out
    if repeats is None:
        repeats = 1 if quick else 3
    setup = _prepare(name, out_dir, quick, check_repeats(repeats), variant, methods, res,
                     scenes_dir, command)
    collected = _Collected(setup, time.perf_counter())
    with _progress(sum(collected.ticks), name, progress) as bar:
        if map_points is None:
            _measure_here(setup, collected, bar)
        else:
            _measure_elsewhere(setup, collected, bar, map_points)
    return {name: collected.finish()}


@dataclass
class _Setup:
    """An experiment ready to measure: what, how, and where it is written."""

    name: str
    experiment: Experiment
    methods: list
    repeats: int
    variant: str
    scenes: Path
    out: Path
    command: str
    env: dict
    cache: Path | None  # converged references kept between runs
    min_seconds: float

    @property
    def denoise(self) -> bool:
        return self.experiment.kind == "denoise"

    @property
    def runner_class(self):
        return DenoiseRunner if self.denoise else PointRunner

    def keep_images_for(self, k: int) -> int | None:
        """The setting of point ``k`` whose images are kept (None: none)."""
        if self.experiment.pictures:
            return 0
        point, setting = self.experiment.representative
        return setting if k == point else None


def _prepare(name, out_dir, quick, repeats, variant, methods, res, scenes_dir,
             command) -> _Setup:
    """Build and check experiment ``name``, activate ``variant``, make the folder."""
    from ..renderer.variants import activate, environment

    experiment = build_experiment(name, quick=quick, res=res)
    variant = activate(variant)
    method_list = resolve_methods(methods if methods is not None else experiment.methods)
    scenes = _scenes_dir(scenes_dir)
    for point in experiment.points:
        if not (scenes / point.scene).is_file():
            raise MRTError(f"scene file not found: {scenes / point.scene}")
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise MRTError(f"cannot create output folder {out}: {exc.strerror}") from None
    if command is None:
        command = "python -m mitsuba_mrt bench " + shlex.join(
            [name, "-o", os.fspath(out_dir)] + (["--quick"] if quick else [])
            + ["--repeats", str(repeats), "--variant", variant]
            + (["--res", str(res)] if res is not None else [])
            + (["--methods", ",".join(method_list[1:])] if methods is not None else []))
    return _Setup(name, experiment, method_list, repeats, variant, scenes, out, command,
                  environment(variant), out / CACHE_DIR if experiment.cache_converged else None,
                  0.0 if quick else MIN_TIMED_SECONDS)


class _Collected:
    """The rows and pictures of the points measured so far, taken in the
    points' order; the CSV rewritten after every point (a crash keeps its
    rows), the report written by :meth:`finish`."""

    def __init__(self, setup: _Setup, started: float):
        self.setup, self.started = setup, started
        self.rows, self.pictures, self.images = [], [], None
        self.csv = setup.out / f"{setup.name}.csv"
        self.ticks = [setup.runner_class.ticks(setup.experiment, p, setup.methods, setup.repeats)
                      for p in setup.experiment.points]

    def take(self, k: int, point_rows, point_images) -> None:
        """Point ``k``'s rows and images (points in order)."""
        setup, points = self.setup, self.setup.experiment.points
        self.rows.extend(point_rows)
        write_csv(self.csv, self.rows, DENOISE_COLUMNS if setup.denoise else CSV_COLUMNS)
        if setup.denoise and k + 1 < len(points):  # its points take minutes each
            _write_report(setup, self.rows, time.perf_counter() - self.started,
                          f"after {k + 1} of {len(points)} scenes")
        if setup.experiment.pictures:
            picture = _picture(setup.out / f"{setup.name}_{Path(points[k].scene).stem}.png",
                               point_rows, point_images, points[k], setup.experiment.pictures)
            self.pictures.extend([picture] if picture else [])
        elif point_images is not None:  # (the representative point's)
            setting = setup.experiment.representative[1]
            self.images = (point_images, points[k], points[k].settings[setting])

    def finish(self) -> ExperimentResult:
        """The plot, the markdown and the triptych of everything taken."""
        setup, seconds = self.setup, time.perf_counter() - self.started
        text_rows, png, md = _write_report(setup, self.rows, seconds)
        triptych = None
        if self.images is not None:
            triptych = _triptych(setup.out / f"{setup.name}_triptych.png", self.rows,
                                 *self.images)
        return ExperimentResult(text_rows, self.csv, png, triptych, md, seconds, self.pictures)


def _measure_here(setup: _Setup, collected: _Collected, bar) -> None:
    """Every point in this process, one after the other."""
    meter = MemoryMeter()
    for k, point in enumerate(setup.experiment.points):
        bar.set_postfix_str(f"{point.scene} {point.defines.get('res')}px", refresh=False)
        runner = setup.runner_class(setup.experiment, point, setup.methods, setup.repeats,
                                    setup.scenes, meter, setup.env, lambda: bar.update(1),
                                    setup.min_seconds, cache_dir=setup.cache)
        collected.take(k, *runner.run(setup.keep_images_for(k)))


def _measure_elsewhere(setup: _Setup, collected: _Collected, bar, map_points) -> None:
    """Every point by one :func:`measure_point` call of ``map_points``, taken in order."""
    # the workers read the scenes and keep the cache at these paths
    calls = [(setup.experiment, k, setup.methods, setup.repeats, setup.scenes.resolve(),
              setup.variant, setup.min_seconds, setup.cache and setup.cache.resolve(),
              setup.keep_images_for(k))
             for k in range(len(setup.experiment.points))]
    done, next_k = {}, 0
    for k, result in map_points(measure_point, calls):
        bar.update(collected.ticks[k])
        done[k] = result
        while next_k in done:
            collected.take(next_k, *done.pop(next_k))
            next_k += 1


def measure_point(experiment, k: int, methods: list, repeats: int, scenes_dir: Path,
                  variant: str, min_seconds: float, cache_dir: Path | None,
                  keep_images_for: int | None) -> tuple:
    """Point ``k`` of ``experiment``, measured where it is called (a Dask worker).

    Activates ``variant`` in this process and measures every method of the
    point here, alternating, as the serial run does; returns the runner's
    ``(rows, images)``, the rows' environment that of this process.
    """
    from ..renderer.variants import activate, environment

    variant = activate(variant)
    runner_class = DenoiseRunner if experiment.kind == "denoise" else PointRunner
    runner = runner_class(experiment, experiment.points[k], methods, repeats, scenes_dir,
                          MemoryMeter(), environment(variant), _no_tick, min_seconds,
                          cache_dir=cache_dir)
    return runner.run(keep_images_for)


def _no_tick():
    """A worker has no progress bar: the client counts finished points."""


def _write_report(setup: _Setup, rows, seconds: float, partial: str = ""):
    """The plot and the markdown of ``rows`` (the CSV's, as written): (text rows, png, md).

    ``partial``: how far a run still going has come (said in the markdown).
    """
    out, name, experiment = setup.out, setup.name, setup.experiment
    text_rows = read_csv(out / f"{name}.csv")
    png = None
    if experiment.kind != "gallery":
        png = out / f"{name}.png"
        plot = {"tradeoff": plot_tradeoff, "denoise": plot_denoise}.get(experiment.kind,
                                                                         plot_sweep)
        plot(text_rows, png, experiment)
    # for denoise, the markdown also says what its CSV leaves out: samplers, stage, failures
    md_rows = [asdict(r) for r in rows] if setup.denoise else text_rows
    md = out / f"{name}.md"
    text = (f"Command: `{setup.command}`\n\n"
            f"Environment: {environment_line(setup.env)}; repeats {setup.repeats}, more where "
            f"the full render is fast (lower median); "
            + (f"written {partial}, {seconds:.0f} s in.\n\n" if partial else
               f"wall time of the whole experiment {seconds:.0f} s.\n\n")
            + markdown_tables(md_rows, experiment))
    with atomic_path(md) as tmp:
        Path(tmp).write_text(text)
    return text_rows, png, md


def _triptych(path, rows, images, point, setting):
    """Reference | the MRT mode of lowest error at ``setting`` | its error map; None if
    no method has an image there."""
    if not images.methods:
        return None
    candidates = [r for r in rows if r.ok and r.scene == point.scene
                  and r.setting == setting.label and r.method in images.methods
                  and r.defines == point.defines_text]
    mrt = [r for r in candidates if r.method.startswith("mrt-")] or candidates
    if not mrt:
        return None
    best = min(mrt, key=lambda r: r.shown_error)
    plot_triptych(path, images.reference, images.methods[best.method],
                  f"{best.method}, {setting.label}: error {best.shown_error:.4f}, "
                  f"time x{best.relative_time:.2f}", _reference_title(images, point))
    return path


def _reference_title(images, point) -> str:
    return (f"converged reference ({CONVERGED_FACTOR * point.spp} spp)"
            if images.converged else f"full render ({point.spp} spp)")


def _picture(path, rows, images, point, methods):
    """Reference | each of ``methods`` that has an image | error map of the first of them;
    None if none has."""
    shown = [m for m in methods if m in images.methods]
    if not shown:
        return None
    by_method = {r.method: r for r in rows if r.ok and r.setting == point.settings[0].label}
    panels = []
    for m in shown:
        title = m
        mode, used = m.removeprefix("mrt-"), images.modes_used.get(m, "")
        if used and used != mode:
            title += f" (ran {used})"
        r = by_method.get(m)
        if r is not None:
            title += f"\nerror {r.shown_error:.4f}, time x{r.relative_time:.2f}"
        panels.append((title, images.methods[m]))
    (title, image), others = panels[0], panels[1:]
    plot_triptych(path, images.reference, image, title, _reference_title(images, point),
                  others=others, error_title=f"error of {shown[0]}, log10")
    return path


def summary_line(name: str, result: ExperimentResult) -> str:
    """One terminal line per experiment."""
    return (f"{name}: {len(result.rows)} rows in {result.seconds:.1f} s -> "
            + ", ".join(os.fspath(f) for f in result.files))

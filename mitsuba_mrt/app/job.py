"""The ``render`` job: MRT + reference of one scene file, outputs on disk.

The command line only parses arguments and calls :func:`run_render_job`.
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..recon.metrics import error_map, paper_error, psnr
from ..types import MRTParams, Skips, Timings, TracedCounts
from ..imageio import (OutputSet, check_output_folder, write_error_png, write_exr, write_json,
                       write_png)


@dataclass
class RenderJob:
    """What to render and where to write it.

    ``params`` and ``mode`` left as None take the scene's ``mrt`` integrator's
    (if it has one), else the defaults; ``param_overrides`` (fields of
    :class:`MRTParams`) are applied on top.
    """

    scene: str
    out_dir: str = "out"
    defines: dict = field(default_factory=dict)
    params: MRTParams | None = None
    param_overrides: dict[str, object] = field(default_factory=dict)
    spp: int | None = None
    seed: int = 0
    variant: str = "auto"
    reference: bool = True
    mode: str | None = None
    progress: bool = False
    sensor: int = 0  # the index of the scene's sensor to render

    def params_for(self, scene_params: MRTParams | None) -> MRTParams:
        """The render's parameters: ``params``, else the scene's, else the
        defaults, with ``param_overrides`` on top (:meth:`MRTParams.with_`,
        which validates them)."""
        return (self.params or scene_params or MRTParams()).with_(**self.param_overrides)

    def stem(self) -> str:
        """The outputs' name (:func:`output_stem`)."""
        return output_stem(self.scene, self.sensor)


def output_stem(scene, sensor: int = 0) -> str:
    """The name of a render's outputs: the scene file's, with ``_sensor<N>``
    for a sensor but the first."""
    stem = Path(scene).stem
    return stem if sensor == 0 else f"{stem}_sensor{sensor}"


@dataclass
class RunSummary:
    """What a render job did, as written to ``<stem>.json``.

    ``reference_time_s``, ``relative_time``, ``error`` and ``psnr_db`` are
    None without a reference; when ``auto`` chose ``mi.render``'s own full
    render, there is no second reference, the time is its own and the
    error None.  ``auto`` is the plan: its candidates with their predicted
    seconds and errors, the choice and why.
    """

    scene: str
    variant: str
    width: int
    height: int
    spp: int
    mode: str
    mode_used: str
    why: str
    sample_fraction: float
    traced: TracedCounts
    timings: Timings
    skipped: Skips
    auto: dict | None
    reference_time_s: float | None
    relative_time: float | None
    error: float | None
    psnr_db: float | None
    params: dict
    defines: dict
    seed: int
    stats: dict
    environment: dict
    outputs: list = field(default_factory=list)
    sensor: int = 0

    def as_dict(self) -> dict:
        return asdict(self)


#: Seconds a render runs before its progress bar shows.
PROGRESS_AFTER = 2.0


@contextlib.contextmanager
def progress_bar(enabled: bool):
    """A ``progress(stage, done)`` callback that draws a tqdm bar on stderr
    once the work has taken :data:`PROGRESS_AFTER` seconds (redrawn twice a
    second, so that its clock runs between stages); nothing where not
    ``enabled`` or stderr is not a terminal."""
    if not (enabled and sys.stderr.isatty()):
        yield lambda stage, done: None
        return
    bar = tqdm(total=100, file=sys.stderr, bar_format="{desc} {bar} {percentage:3.0f}% {elapsed}",
               delay=PROGRESS_AFTER, leave=False)
    closed = threading.Event()

    def redraw() -> None:
        if not closed.wait(PROGRESS_AFTER):
            while not closed.wait(0.5):
                bar.refresh()

    def tell(stage: str, done: float) -> None:
        bar.set_description_str(stage, refresh=False)
        bar.update(max(0, round(100 * done) - bar.n))

    thread = threading.Thread(target=redraw, daemon=True)
    thread.start()
    try:
        yield tell
    finally:
        closed.set()
        thread.join()
        bar.close()


def _why(result) -> str:
    """Why the mode that ran was chosen, in a few words."""
    plan = result.auto
    if plan is None:
        return "asked for"
    choice = plan.choice
    text = f"auto: {choice.label}, {plan.reason}"
    if choice.error is not None:
        name = "a full render's" if choice.kind == "mrt" else "target"  # (mrt: its check's)
        target = ("" if plan.target_error is None or plan.target_error == choice.error
                  else f", {name} {plan.target_error:.4f}")
        estimate = (f"{choice.error:.4f}" if choice.error > 0 or choice.kind != "mrt"
                    else "below what its check resolves")  # (its noise outweighed the error)
        text += f" (estimated error {estimate}{target})"
    return text


def run_render_job(job: RenderJob) -> RunSummary:
    """Render ``job.scene`` with the MRT (and the reference), write outputs.

    Files written into ``job.out_dir``, together or not at all, with
    ``stem`` the scene file's name (:meth:`RenderJob.stem`): ``stem_mrt.exr`` (R, G, B, id,
    shape_index, visible_lights, traced), ``stem_mrt.png``, and with the
    reference ``stem_ref.exr``, ``stem_ref.png``, ``stem_error.png``; last
    ``stem.json``, the returned summary.
    """
    from ..renderer.api import render, render_reference
    from ..renderer.aovs import aov_images
    from ..renderer.scene import load_scene, unwrap
    from ..renderer.variants import activate, environment

    check_output_folder(job.out_dir)  # before any work
    variant = activate(job.variant)
    with progress_bar(job.progress) as tell:
        tell("load", 0.0)
        scene = load_scene(job.scene, **job.defines)  # checks the film's size
        params = job.params_for(unwrap(scene).params)
        result = render(scene, sensor=job.sensor, spp=job.spp, seed=job.seed, params=params,
                        mode=job.mode, progress=tell)
    stem = job.stem()
    height, width = result.ids.shape
    full = result.mode_used == "full"
    reference = None
    if job.reference and not full:
        # at the scene's (or the job's) spp: a plan may trace fewer
        with progress_bar(job.progress) as tell:
            tell("reference", 0.0)
            reference, seconds = render_reference(scene, sensor=job.sensor, spp=job.spp,
                                                  seed=job.seed)
        # (the reference's alpha is the film's; only RGB is compared and written)
    summary = RunSummary(
        scene=os.fspath(job.scene), variant=variant, width=width, height=height,
        spp=result.spp, mode=result.mode, mode_used=result.mode_used, why=_why(result),
        sample_fraction=result.params.sample_fraction, traced=result.traced,
        timings=result.timings, skipped=result.skips,
        auto=asdict(result.auto) if result.auto else None,
        reference_time_s=(result.timings.full_render if full else
                          seconds if reference is not None else None),
        relative_time=None, error=None, psnr_db=None,
        params=result.params.as_dict(), defines=dict(job.defines), seed=job.seed,
        sensor=job.sensor,
        stats=dict(result.stats), environment=environment(variant))
    if full:
        summary.relative_time = result.timings.total / result.timings.full_render
    elif reference is not None:
        summary.relative_time = result.timings.total / seconds
        summary.error = paper_error(result.image, reference)
        summary.psnr_db = psnr(result.image, reference)

    channels = {"R": result.image[..., 0], "G": result.image[..., 1], "B": result.image[..., 2]}
    rgba = scene.sensors()[job.sensor].film().base_channels_count() == 4
    if rgba and result.alpha is not None:
        channels["A"] = result.alpha
    for name, image in aov_images(result).items():
        channels[name] = image.astype(np.uint32) if name != "id" else image
    with OutputSet(job.out_dir) as out:
        write_exr(out.path(f"{stem}_mrt.exr"), channels)
        write_png(out.path(f"{stem}_mrt.png"), result.image)
        if reference is not None:
            write_exr(out.path(f"{stem}_ref.exr"),
                      {c: reference[..., k] for k, c in enumerate("RGB")})
            write_png(out.path(f"{stem}_ref.png"), reference)
            write_error_png(out.path(f"{stem}_error.png"), error_map(result.image, reference))
        json_path = out.path(f"{stem}.json")
        summary.outputs = out.names
        write_json(json_path, summary.as_dict())
    return summary


def _compiled(count: int) -> str:
    """The summary line's note of kernels compiled (none: nothing)."""
    return f" ({count} kernel{'s' if count != 1 else ''} compiled)" if count else ""


def summary_line(summary: RunSummary) -> str:
    """One terminal line: what was traced and why, where the time went, the error."""
    s, t, traced = summary, summary.timings, summary.traced
    pixels = s.width * s.height
    parts = [f"{n} {label}" for n, label in ((traced.grid, "grid"),
                                             (traced.more, _more_label(s.mode_used)),
                                             (traced.full, "full render")) if n]
    name = Path(s.scene).stem + (f", sensor {s.sensor}" if s.sensor else "")
    line = (f"{name}: {s.width}x{s.height}, mode {s.mode_used} ({s.why}); "
            f"traced {' + '.join(parts) or 'nothing'} = "
            f"{100.0 * traced.total / pixels:.1f}% of the pixels; "
            f"{t.total:.3f} s = trace {t.trace:.3f} + more {t.trace_more:.3f}"
            f"{f' + pilot {t.check:.3f}' if t.check else ''}"
            f"{f' + denoise {t.denoise:.3f}' if t.denoise else ''}"
            f" + edges {t.edges:.3f} + interpolate {t.interpolate:.3f}"
            f"{f' + full render {t.full_render:.3f}' if t.full_render else ''}"
            f" + other {t.other:.3f}"
            f"{_compiled(t.compile.compiled)}")
    if s.error is not None:
        line += (f"; reference {s.reference_time_s:.3f} s ({s.relative_time:.2f}x), "
                 f"error {s.error:.5f}, PSNR {s.psnr_db:.2f} dB")
    elif s.mode_used == "full":
        line += "; the image is the full render (no second reference)"
    return line + f" [{s.variant}]"


def _more_label(mode_used: str) -> str:
    return {"refine": "at edges", "idpass": "in thin regions"}.get(mode_used, "more")

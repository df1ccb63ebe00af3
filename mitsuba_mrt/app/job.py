"""The ``render`` job: MRT + reference of one scene file, outputs on disk.

The command line only parses arguments and calls :func:`run_render_job`.
"""

from __future__ import annotations

import os
import platform
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import MRTError
from .imageio import write_error_png, write_exr, write_json, write_png
from .metrics import error_map, paper_error, psnr
from .pipeline import MRTParams


@dataclass
class RenderJob:
    """What to render and where to write it."""

    scene: str
    out_dir: str = "out"
    defines: dict = field(default_factory=dict)
    params: MRTParams = field(default_factory=MRTParams)
    spp: int | None = None
    seed: int = 0
    variant: str = "auto"
    reference: bool = True
    mode: str = "auto"


def _environment(variant: str) -> dict:
    import drjit as dr
    import mitsuba as mi

    return {"variant": variant, "mitsuba": mi.__version__, "drjit": dr.__version__,
            "cpu_count": os.cpu_count(), "machine": platform.machine(),
            "python": platform.python_version()}


def run_render_job(job: RenderJob) -> dict:
    """Render ``job.scene`` with the MRT (and the reference), write outputs.

    Files written into ``job.out_dir`` (each atomically), with ``stem`` the
    scene file's name: ``stem_mrt.exr`` (R, G, B, id, shape_index,
    visible_lights, traced), ``stem_mrt.png``, and with the reference
    ``stem_ref.exr``, ``stem_ref.png``, ``stem_error.png``; last
    ``stem.json``, the returned summary.
    """
    from .variants import activate

    if not os.path.isfile(job.scene):
        raise MRTError(f"scene file not found: {job.scene}")
    variant = activate(job.variant)
    from .api import load_scene, render, render_reference
    from .plugins import aov_images

    scene = load_scene(job.scene, **job.defines)
    result = render(scene, spp=job.spp, seed=job.seed, params=job.params, mode=job.mode)
    out = Path(job.out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise MRTError(f"cannot create output folder {out}: {exc.strerror}") from None
    stem = Path(job.scene).stem
    height, width = result.ids.shape
    summary = {
        "scene": os.fspath(job.scene), "variant": variant, "width": width,
        "height": height, "spp": result.spp, "mode": result.mode,
        "mode_used": result.stats.get("mode_used", result.mode),
        "skipped": {k[len("skipped_"):]: v for k, v in result.stats.items()
                    if k.startswith("skipped_")},
        "sample_fraction": result.params.sample_fraction,
        "traced_pixels": int(result.traced_mask.sum()),
        "timings": {k: result.timings[k] for k in ("trace", "edges", "interpolate", "total")},
        "reference_time_s": None, "relative_time": None, "error": None, "psnr_db": None,
        "params": result.params.as_dict(), "defines": dict(job.defines), "seed": job.seed,
        "stats": {k: v for k, v in result.stats.items() if not k.startswith("skipped_")}, "environment": _environment(variant), "outputs": [],
    }
    files = summary["outputs"]
    channels = {"R": result.image[..., 0], "G": result.image[..., 1], "B": result.image[..., 2]}
    for name, image in aov_images(result).items():
        channels[name] = image.astype(np.uint32) if name != "id" else image
    write_exr(out / f"{stem}_mrt.exr", channels)
    write_png(out / f"{stem}_mrt.png", result.image)
    files += [f"{stem}_mrt.exr", f"{stem}_mrt.png"]
    if job.reference:
        reference, seconds = render_reference(scene, spp=result.spp, seed=job.seed)
        summary.update(reference_time_s=seconds,
                       relative_time=result.timings["total"] / seconds,
                       error=paper_error(result.image, reference),
                       psnr_db=psnr(result.image, reference))
        write_exr(out / f"{stem}_ref.exr", {c: reference[..., k] for k, c in enumerate("RGB")})
        write_png(out / f"{stem}_ref.png", reference)
        write_error_png(out / f"{stem}_error.png", error_map(result.image, reference))
        files += [f"{stem}_ref.exr", f"{stem}_ref.png", f"{stem}_error.png"]
    files.append(f"{stem}.json")
    write_json(out / f"{stem}.json", summary)
    return summary


def summary_line(summary: dict) -> str:
    """One terminal line describing a render job's summary."""
    t = summary["timings"]
    line = (f"{Path(summary['scene']).stem}: {summary['width']}x{summary['height']}, "
            f"{summary['traced_pixels']} pixels traced "
            f"({100.0 * summary['traced_pixels'] / (summary['width'] * summary['height']):.1f}%), "
            f"MRT {t['total']:.3f} s (trace {t['trace']:.3f}, edges {t['edges']:.3f}, "
            f"interpolate {t['interpolate']:.3f})")
    if summary["reference_time_s"] is not None:
        line += (f", reference {summary['reference_time_s']:.3f} s, "
                 f"error {summary['error']:.5f}, PSNR {summary['psnr_db']:.2f} dB")
    used = summary["mode_used"]
    return line + f" [{summary['variant']}, mode {used}]"

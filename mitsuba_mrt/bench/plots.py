"""The plots and pictures of a bench experiment (matplotlib, headless, on first use).

Each plot reads rows as the CSV holds them (:func:`.analysis.read_csv`):

- ``<experiment>.png``: error and relative time against the swept parameter
  (:func:`plot_sweep`); for ``tradeoff``, time against error
  (:func:`plot_tradeoff`); for ``denoise``, error against time, a panel per
  scene, a curve per method (:func:`plot_denoise`);
- ``<experiment>_triptych.png``: reference | MRT | error map of one setting
  (:func:`plot_triptych`); for ``gallery``, ``gallery_<scene>.png``:
  reference | ``auto`` | ``bicubic`` | error map of ``auto``, per scene.
"""

from __future__ import annotations

import math

import numpy as np

from ..imageio import atomic_path, srgb_encode
from ..recon.metrics import error_map
from .analysis import (EQUAL_TIME_UP_TO, denoise_curves, error_of, is_mrt, num, ok_rows,
                       reference_error, sweep_series)
from .experiments import EQUAL_TIME_BASELINES, FULL, OIDN, OIDN_NOAUX, Experiment, denoised_mode


def _figure(width, height):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height))
    FigureCanvasAgg(fig)
    return fig


def _plain_ticks(axis):
    """Tick labels of a log axis as plain numbers (0.02, not 2 x 10^-2)."""
    from matplotlib.ticker import FuncFormatter

    fmt = FuncFormatter(lambda v, _pos: f"{v:g}")
    axis.set_major_formatter(fmt)
    axis.set_minor_formatter(FuncFormatter(
        lambda v, _pos: f"{v:g}" if f"{v:.0e}"[0] in "25" else ""))


def _save(fig, path, dpi=80, palette=False):
    """Save ``fig`` as PNG; ``palette``: 256 dithered colours (noisy renders stay small)."""
    with atomic_path(path) as tmp:
        if palette:
            try:
                from PIL import Image  # matplotlib's own dependency
            except ImportError:  # pragma: no cover
                palette = False
        if not palette:
            fig.savefig(tmp, format="png", dpi=dpi)
            return
        fig.set_dpi(dpi)
        fig.canvas.draw()
        rgb = np.asarray(fig.canvas.buffer_rgba())[..., :3]
        image = Image.fromarray(np.ascontiguousarray(rgb))
        # an adaptive palette, then Floyd-Steinberg dithering: no banding in gradients
        palette_image = image.quantize(colors=256, method=Image.Quantize.MEDIANCUT)
        image.quantize(palette=palette_image, dither=Image.Dither.FLOYDSTEINBERG).save(
            tmp, format="PNG", optimize=True)


def plot_sweep(rows, path, experiment: Experiment) -> None:
    """Error and relative time against the swept value (headless).

    One colour per method; with groups (the filter test's sigma) one line
    style per group.
    """
    from matplotlib.lines import Line2D

    rows = ok_rows(rows)
    series = sweep_series(rows, experiment.name)
    methods = list(dict.fromkeys(m for m, _ in series))
    groups = list(dict.fromkeys(g for _, g in series if g))
    styles = ("-", "--", ":", "-.")
    markers = "os^Dv<>ph*"
    fig = _figure(10.0, 3.6)
    ax_err, ax_time = fig.subplots(1, 2)
    for (method, group), pts in series.items():
        k = methods.index(method)
        g = groups.index(group) if group else 0
        style = dict(color=f"C{k % 10}", ls=styles[g % len(styles)],
                     marker=markers[g % len(markers)], ms=3, lw=1.2)
        xs = [p[0] for p in pts]
        ax_err.plot(xs, [error_of(p[1]) for p in pts], **style)
        ax_time.plot(xs, [num(p[1]["relative_time"]) for p in pts], **style)
    ax_time.axhline(1.0, color="k", lw=1, ls="--")
    ax_err.set_ylabel("error (report's metric)")
    ax_time.set_ylabel("relative time (method / full)")
    ax_time.set_yscale("log")
    _plain_ticks(ax_time.yaxis)
    for ax in (ax_err, ax_time):
        ax.set_xlabel(experiment.x_label)
        ax.grid(True, alpha=0.3)
    ax_err.set_ylim(bottom=0)
    handles = [Line2D([], [], color=f"C{k % 10}", lw=2, label=m) for k, m in enumerate(methods)]
    handles += [Line2D([], [], color="gray", ls=styles[g % len(styles)],
                       marker=markers[g % len(markers)], ms=3, label=group)
                for g, group in enumerate(groups)]
    handles.append(Line2D([], [], color="k", ls="--", lw=1, label="full render"))
    fig.legend(handles=handles, loc="center right", fontsize=7, frameon=False)
    fig.suptitle(f"{experiment.name}: {experiment.title}", fontsize=9)
    fig.tight_layout(rect=(0, 0, 0.83, 1))
    _save(fig, path)


def plot_tradeoff(rows, path, experiment: Experiment) -> None:
    """Total time (log) against error (log), one panel per group, one marker per method."""
    rows = ok_rows(rows)
    groups = list(dict.fromkeys(r["group"] for r in rows))
    fig = _figure(4.6 * max(len(groups), 1), 3.8)
    axes = np.atleast_1d(fig.subplots(1, max(len(groups), 1)))
    methods = list(dict.fromkeys(r["method"] for r in rows if r["method"] not in (
        FULL, OIDN, OIDN_NOAUX, *EQUAL_TIME_BASELINES)))
    markers = "osD^v<>ph*"
    for ax, group in zip(axes, groups):
        grows = [r for r in rows if r["group"] == group]
        for name, style in ((FULL, "k-o"), (OIDN, "k--s"), (OIDN_NOAUX, "k:^")):
            spp_curve = sorted([r for r in grows if r["method"] == name],
                               key=lambda r: num(r["total_s"]))
            errs = [error_of(r) for r in spp_curve]
            if not (spp_curve and all(e > 0 for e in errs)):
                continue
            ax.plot([num(r["total_s"]) for r in spp_curve], errs, style, ms=4,
                    mfc="none" if name != FULL else None, label=f"{name} (spp)")
            for r, e in zip(spp_curve if name == FULL else [], errs):
                ax.annotate(f"{r['spp']} spp", (num(r["total_s"]), e), fontsize=6,
                            xytext=(3, 3), textcoords="offset points")
        full = [r for r in grows if r["method"] == FULL]
        for r in full:
            if error_of(r) <= 0:
                ax.axvline(num(r["total_s"]), color="k", ls="--", lw=1,
                           label="full (exact)")
        for k, m in enumerate(methods):
            pts = sorted([r for r in grows if r["method"] == m],
                         key=lambda r: num(r["sample_fraction"]))
            if not pts:
                continue
            xs, ys = [num(r["total_s"]) for r in pts], [error_of(r) for r in pts]
            ax.plot(xs, ys, marker=markers[k % len(markers)], ms=4, lw=0.8, label=m,
                    color=f"C{k % 10}")
            for r, x, y in zip(pts, xs, ys):
                ax.annotate(f"{num(r['sample_fraction']):g}", (x, y), fontsize=6,
                            xytext=(3, -8), textcoords="offset points")
        ax.set_xscale("log")
        ax.set_yscale("log")
        _plain_ticks(ax.xaxis), _plain_ticks(ax.yaxis)
        conv = any(math.isfinite(num(r.get("error_converged"))) for r in grows)
        ax.set_ylabel("error vs converged reference" if conv else "error vs full render")
        ax.set_xlabel("total time (s), median")
        ax.set_title(group, fontsize=8)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=6, loc="best")
    fig.suptitle(f"{experiment.name}: {experiment.title}; labels: sample fraction", fontsize=8)
    fig.tight_layout()
    _save(fig, path)


def plot_triptych(path, reference, image, title: str, reference_title="reference", *,
                  others=(), error_title="error, log10") -> None:
    """Reference | MRT | error map of the MRT (log10 of the report's per-pixel error).

    ``others``: more (title, image) panels, drawn between the MRT and its
    error map.
    """
    panels = [(reference_title, reference), (title, image), *others]
    fig = _figure(3.0 * (len(panels) + 1), 3.3)
    axes = fig.subplots(1, len(panels) + 1)
    for ax, (panel_title, panel) in zip(axes, panels):
        ax.imshow(srgb_encode(panel))
        ax.set_title(panel_title, fontsize=8)
    errors = np.log10(np.clip(error_map(image, reference), 1e-4, 1.0))
    im = axes[-1].imshow(errors, vmin=-4, vmax=0, cmap="inferno")
    axes[-1].set_title(error_title, fontsize=8)
    fig.colorbar(im, ax=axes[-1], fraction=0.046, pad=0.04)
    for ax in axes:
        ax.set_xticks([]), ax.set_yticks([])
    fig.tight_layout()
    _save(fig, path, palette=True)


def plot_denoise(rows, path, experiment: Experiment) -> None:
    """Error (log) against relative time (log): a panel per scene, a curve per method.

    MRT modes in colour (dashed: with ``denoise``), the full render black,
    ``oidn`` grey (dashed: without guides; open markers: balanced quality);
    the dotted lines are the full render's error and the equal-time limit.
    """
    from matplotlib.lines import Line2D

    scenes = denoise_curves(rows)
    n = max(len(scenes), 1)
    cols = min(n, 5)
    nrows = math.ceil(n / cols)
    fig = _figure(3.2 * cols + 1.8, 2.9 * nrows)
    axes = np.atleast_1d(fig.subplots(nrows, cols, squeeze=False)).ravel()
    modes = list(dict.fromkeys(denoised_mode(label.split()[0])[0]
                               for curves in scenes.values() for label in curves
                               if is_mrt(label)))
    handles = {}
    for ax, (group, curves) in zip(axes, scenes.items()):
        e64, _ = reference_error(curves)
        for label, pts in curves.items():
            if label == FULL:
                style = dict(color="k", ls="-", marker="o")
            elif label.split()[0] in (OIDN, OIDN_NOAUX):
                method, quality = (label.split() + [""])[:2]
                style = dict(color="0.55", ls="--" if method == OIDN_NOAUX else "-",
                             marker="s", mfc="none" if quality == "balanced" else "0.55")
            else:
                mode, denoised = denoised_mode(label.split()[0])
                k = modes.index(mode)
                fraction = (label.split() + [""])[1]
                style = dict(color=f"C{k % 10}",
                             marker={"": "^", "f=0.05": "v", "f=0.2": "D"}.get(fraction, "x"),
                             ls=":" if denoised.count("-") else "--" if denoised else "-")
            line, = ax.plot([p[0] for p in pts], [p[1] for p in pts], ms=3, lw=1.0, **style)
            handles.setdefault(label, line)
        if math.isfinite(e64):
            ax.axhline(e64, color="k", ls=":", lw=0.8)
        ax.axvline(EQUAL_TIME_UP_TO, color="r", ls=":", lw=0.8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        _plain_ticks(ax.xaxis), _plain_ticks(ax.yaxis)
        ax.set_title(group, fontsize=8)
        ax.tick_params(labelsize=6)
        ax.grid(True, which="both", alpha=0.3)
    for ax in axes[len(scenes):]:
        ax.set_visible(False)
    for ax in axes[::cols]:
        ax.set_ylabel("error vs converged", fontsize=7)
    for ax in axes[-cols:]:
        ax.set_xlabel("time / full render at top spp", fontsize=7)
    extra = [Line2D([], [], color="k", ls=":", lw=0.8, label="full render's error"),
             Line2D([], [], color="r", ls=":", lw=0.8,
                    label=f"equal time up to {EQUAL_TIME_UP_TO:g}")]
    fig.legend(handles=list(handles.values()) + extra,
               labels=list(handles) + [h.get_label() for h in extra],
               loc="center right", fontsize=6, frameon=False)
    beyond = sorted({int(num(p[2]["spp"])) for curves in scenes.values()
                     for pts in curves.values() for p in pts} - set(experiment.ladder))
    fig.suptitle(f"{experiment.name}: {experiment.title}; each curve: spp "
                 f"{', '.join(str(s) for s in experiment.ladder)}"
                 + (f" (some MRT curves also {', '.join(map(str, beyond))})" if beyond else ""),
                 fontsize=8)
    fig.tight_layout(rect=(0, 0, 1 - 1.6 / (3.2 * cols + 1.8), 1))
    _save(fig, path)

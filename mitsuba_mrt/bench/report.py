"""Reporting a bench experiment: its CSV, plots, pictures and markdown tables.

The CSV has one row per method and setting (:class:`.measure.MethodRow`,
whose fields are :data:`CSV_COLUMNS`). Everything else here reads rows back
as the CSV holds them, dicts of strings (:func:`read_csv`), so a plot or a
table can be redrawn from a CSV alone:

- ``<experiment>.png``: error and relative time against the swept parameter
  (:func:`plot_sweep`); for ``tradeoff``, time against error
  (:func:`plot_tradeoff`);
- ``<experiment>_triptych.png``: reference | MRT | error map of one setting
  (:func:`plot_triptych`); for ``gallery``, ``gallery_<scene>.png``:
  reference | ``auto`` | ``bicubic`` | error map of ``auto``, per scene;
- ``<experiment>.md``: the tables (:func:`markdown_tables`); for
  ``gallery`` one table, a row per scene and method.
"""

from __future__ import annotations

import csv
import math
from dataclasses import asdict, fields

import numpy as np

from ..app.imageio import atomic_path, srgb_encode
from .experiments import BASELINES, EQUAL_TIME, FULL, Experiment
from .measure import CONVERGED_FACTOR, MethodRow

#: Columns of every CSV, in order: the fields of :class:`MethodRow`.
CSV_COLUMNS = tuple(f.name for f in fields(MethodRow))


def _fmt(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (float, np.floating)):
        value = float(value)
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return f"{value:.6g}"
    return "" if value is None else str(value)


def write_csv(path, rows) -> None:
    """Write ``rows`` (:class:`MethodRow` s) with :data:`CSV_COLUMNS`."""
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(CSV_COLUMNS)
            for r in rows:
                values = asdict(r)
                writer.writerow([_fmt(values[c]) for c in CSV_COLUMNS])


def read_csv(path) -> list[dict]:
    """Rows of a bench CSV as dicts of strings."""
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _num(value) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def _ok(rows):
    return [r for r in rows if r.get("status", "ok") == "ok"]


def _error_of(r) -> float:
    """The error a plot shows: against the converged reference when there is one."""
    conv = _num(r.get("error_converged"))
    return conv if math.isfinite(conv) else _num(r.get("error"))


def _psnr_of(r) -> float:
    """PSNR against the converged reference when there is one, else the full render."""
    if math.isfinite(_num(r.get("error_converged"))):
        return _num(r.get("psnr_converged_db"))
    return _num(r.get("psnr_db"))


def _series(rows, experiment_name):
    """Lines of a sweep plot: {(method, group): sorted [(x, row)]}; baselines once."""
    lines = {}
    groups = sorted({r["group"] for r in rows if r["method"] != FULL}, key=_group_key)
    for r in rows:
        m = r["method"]
        if m in (FULL, EQUAL_TIME) or not math.isfinite(_num(r["x"])):
            continue
        if m in BASELINES and groups and r["group"] != groups[0]:
            continue
        key = (m, "" if m in BASELINES else r["group"])
        lines.setdefault(key, []).append((_num(r["x"]), r))
    return {k: sorted(v, key=lambda p: p[0]) for k, v in lines.items()}


def _group_key(g: str):
    try:
        return (0, float(g.split("=", 1)[1]))
    except (IndexError, ValueError):
        return (1, g)


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

    rows = _ok(rows)
    series = _series(rows, experiment.name)
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
        ax_err.plot(xs, [_error_of(p[1]) for p in pts], **style)
        ax_time.plot(xs, [_num(p[1]["relative_time"]) for p in pts], **style)
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
    rows = _ok(rows)
    groups = list(dict.fromkeys(r["group"] for r in rows))
    fig = _figure(4.6 * max(len(groups), 1), 3.8)
    axes = np.atleast_1d(fig.subplots(1, max(len(groups), 1)))
    methods = list(dict.fromkeys(r["method"] for r in rows
                                 if r["method"] not in (FULL, EQUAL_TIME)))
    markers = "osD^v<>ph*"
    for ax, group in zip(axes, groups):
        grows = [r for r in rows if r["group"] == group]
        full = sorted([r for r in grows if r["method"] == FULL], key=lambda r: _num(r["total_s"]))
        errs = [_error_of(r) for r in full]
        if full and all(e > 0 for e in errs):
            ax.plot([_num(r["total_s"]) for r in full], errs, "k-o", ms=4, label="full (spp)")
            for r, e in zip(full, errs):
                ax.annotate(f"{r['spp']} spp", (_num(r["total_s"]), e), fontsize=6,
                            xytext=(3, 3), textcoords="offset points")
        for r in full:
            if _error_of(r) <= 0:
                ax.axvline(_num(r["total_s"]), color="k", ls="--", lw=1,
                           label="full (exact)")
        for k, m in enumerate(methods):
            pts = sorted([r for r in grows if r["method"] == m],
                         key=lambda r: _num(r["sample_fraction"]))
            if not pts:
                continue
            xs, ys = [_num(r["total_s"]) for r in pts], [_error_of(r) for r in pts]
            ax.plot(xs, ys, marker=markers[k % len(markers)], ms=4, lw=0.8, label=m,
                    color=f"C{k % 10}")
            for r, x, y in zip(pts, xs, ys):
                ax.annotate(f"{_num(r['sample_fraction']):g}", (x, y), fontsize=6,
                            xytext=(3, -8), textcoords="offset points")
        ax.set_xscale("log")
        ax.set_yscale("log")
        _plain_ticks(ax.xaxis), _plain_ticks(ax.yaxis)
        conv = any(math.isfinite(_num(r.get("error_converged"))) for r in grows)
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
    from ..recon.metrics import error_map

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


def _md_number(value, digits=4) -> str:
    v = _num(value)
    if not math.isfinite(v):
        return "-" if math.isnan(v) else _fmt(v)
    return f"{v:.{digits}g}"


def markdown_tables(rows, experiment: Experiment) -> str:
    """The experiment's tables as markdown (no heading, no command)."""
    ok = _ok(rows)
    tables = {"tradeoff": _tradeoff_table, "gallery": _gallery_table}.get(experiment.kind,
                                                                           _sweep_tables)
    out = tables(ok, experiment)
    failed = [r for r in rows if r.get("status", "ok") != "ok"]
    if failed:
        where = "group" if experiment.kind == "gallery" else "setting"
        out.append("")
        out.append("Failed runs: " + "; ".join(f"{r['method']} {r[where]}: {r['status']}"
                                               for r in failed))
    return "\n".join(out).rstrip() + "\n"


def _tradeoff_table(ok, experiment: Experiment) -> list:
    """One row per method and setting: time, error against the full render and the
    converged reference."""
    out = []
    stoch = any(r.get("stochastic") in (True, "true") for r in ok)
    head = ["group", "method", "setting", "spp", "total s", "relative time",
            "error vs full"] + (["error vs converged", "PSNR vs converged dB"] if stoch
                                else ["PSNR dB"])
    out.append("| " + " | ".join(head) + " |")
    out.append("|" + " --- |" * len(head))
    for r in ok:
        label = r["setting"] + (f" (time of {r['matched_method']})"
                                if r["method"] == EQUAL_TIME else "")
        cells = [r["group"], r["method"], label, r["spp"], _md_number(r["total_s"]),
                 _md_number(r["relative_time"], 3), _md_number(r["error"])]
        cells += ([_md_number(r["error_converged"]), _md_number(r["psnr_converged_db"], 4)]
                  if stoch else [_md_number(r["psnr_db"], 4)])
        out.append("| " + " | ".join(str(c) for c in cells) + " |")
    return out


def _sweep_tables(ok, experiment: Experiment) -> list:
    """A table per measure (error, relative time, ...): a row per method, a column per x."""
    out = []
    lines = _series(ok, experiment.name)
    xs = sorted({x for pts in lines.values() for x, _ in pts})
    head = "| method | " + " | ".join(f"{x:g}" for x in xs) + " |"
    sep = "| --- |" + " ---: |" * len(xs)
    full = {}
    for r in ok:
        if r["method"] == FULL and math.isfinite(_num(r["x"])):
            full[_num(r["x"])] = r
    if not full:  # one point, several settings: the full render is shared
        shared = [r for r in ok if r["method"] == FULL]
        full = {x: shared[0] for x in xs} if shared else {}
    for title, column, digits in (
            (f"Error (the report's metric, against the full render) by {experiment.x_label}",
             "error", 4),
            ("Relative time (median method total / median full render)", "relative_time", 3),
            ("Relative time of the fastest runs (fewest interruptions: min method total / "
             "min full render)", "relative_min", 3),
            ("Median total time (s)", "total_s", 3)):
        out += [f"{title}:", "", head, sep]
        for (method, group), pts in lines.items():
            by_x = {x: dict(r, relative_min=_num(r.get("total_min_s")) / _num(
                (full.get(x) or {}).get("total_min_s"))) for x, r in pts}
            label = method if not group else f"{method} {group}"
            out.append(f"| {label} | " + " | ".join(
                _md_number(by_x[x][column], digits) if x in by_x else "-" for x in xs) + " |")
        if column == "total_s" and full:
            out.append("| full | " + " | ".join(
                _md_number(full[x]["total_s"], digits) if x in full else "-" for x in xs)
                + " |")
        out.append("")
    warm = [r for r in ok if r["method"] != EQUAL_TIME]
    if warm:
        first_scene = warm[0].get("scene"), warm[0].get("defines")
        seen = {}
        for r in warm:
            if (r.get("scene"), r.get("defines")) == first_scene and r["method"] not in seen:
                seen[r["method"]] = (r.get("warmup_s"), r["total_s"])
        out.append("First call at the first point (kernel compilation included; excluded "
                   "from the medians above), s: " + ", ".join(
                       f"{m} {_md_number(w, 3)} (then {_md_number(t, 3)})"
                       for m, (w, t) in seen.items()) + ".")
    return out


def _gallery_table(ok, experiment: Experiment) -> list:
    """One table, a row per scene and method, and the methods that made a pixel below 0
    where the full render has none."""
    out = [f"Error (the report's metric) and PSNR against the converged reference (the mean "
           f"of {CONVERGED_FACTOR} full renders, {CONVERGED_FACTOR}x the spp) where the "
           "integrator is stochastic, else against the full render; relative time: median "
           "method total / median full render; min value: the lowest channel value of the "
           "image.", ""]
    head = ["scene", "method", "spp", "relative time", "error", "PSNR dB", "min value"]
    out.append("| " + " | ".join(head) + " |")
    out.append("| --- | --- |" + " ---: |" * (len(head) - 2))
    for r in ok:
        method = r["method"] + (f" (time of {r['matched_method']})"
                                if r["method"] == EQUAL_TIME else "")
        cells = [r["group"], method, r["spp"], _md_number(r["relative_time"], 3),
                 _md_number(_error_of(r)), _md_number(_psnr_of(r), 4),
                 _md_number(r.get("min_value"), 3)]
        out.append("| " + " | ".join(str(c) for c in cells) + " |")
    negative = []
    for scene in dict.fromkeys(r["group"] for r in ok):
        rows = [r for r in ok if r["group"] == scene]
        full = [r for r in rows if r["method"] == FULL]
        if not full or not _num(full[0].get("min_value")) >= 0:
            continue
        below = [f"{r['method']} ({_md_number(r['min_value'], 3)})" for r in rows
                 if r["method"] not in (FULL, EQUAL_TIME) and _num(r.get("min_value")) < 0]
        if below:
            negative.append(f"{scene}: " + ", ".join(below))
    out += ["", "Pixels below 0 where the full render has none: "
            + ("; ".join(negative) if negative else "none") + "."]
    return out


def environment_line(env: dict) -> str:
    return (f"{env['variant']}, Mitsuba {env['mitsuba']}, Dr.Jit {env['drjit']}, "
            f"{env['cpu_count']} CPUs ({env['cpu_model']}, {env['machine']}), "
            f"{env['platform']}, Python {env['python']}")

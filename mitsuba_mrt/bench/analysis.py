"""The numbers of a bench experiment: its CSV, the verdicts and the markdown tables.

The CSV has one row per method and setting (:class:`.records.MethodRow`,
whose fields are :data:`CSV_COLUMNS`). Everything else here reads rows back
as the CSV holds them, dicts of strings (:func:`read_csv`), so a table (or
a plot, :mod:`.plots`) can be redrawn from a CSV alone:
``<experiment>.md`` holds the tables (:func:`markdown_tables`); for
``gallery`` one table, a row per scene and method.

The ``denoise`` experiment has its own CSV columns
(:data:`.records.DENOISE_COLUMNS`), curves (:func:`denoise_curves`: error
against time, per scene and method) and tables (:func:`denoise_tables`:
equal time, equal error, and the verdicts on the targets of issue 15).
"""

from __future__ import annotations

import csv
import math
from dataclasses import asdict, fields

import numpy as np

from ..imageio import atomic_path
from ..types import MRTParams
from .experiments import (BASELINES, EQUAL_TIME_BASELINES, FULL, OIDN, OIDN_NOAUX,
                          Experiment, denoised_mode)
from .records import CONVERGED_FACTOR, NOISE_FREE, MethodRow

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


def write_csv(path, rows, columns=CSV_COLUMNS) -> None:
    """Write ``rows`` (dataclasses: :class:`MethodRow` s) with ``columns``."""
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(columns)
            for r in rows:
                values = asdict(r)
                writer.writerow([_fmt(values[c]) for c in columns])


def read_csv(path) -> list[dict]:
    """Rows of a bench CSV as dicts of strings."""
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def num(value) -> float:
    """A CSV cell as a float; NaN where it holds no number."""
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def ok_rows(rows):
    """The rows whose status is ``ok``."""
    return [r for r in rows if r.get("status", "ok") == "ok"]


def error_of(r) -> float:
    """The error a plot shows: against the converged reference when there is one."""
    conv = num(r.get("error_converged"))
    return conv if math.isfinite(conv) else num(r.get("error"))


def _psnr_of(r) -> float:
    """PSNR against the converged reference when there is one, else the full render."""
    if math.isfinite(num(r.get("error_converged"))):
        return num(r.get("psnr_converged_db"))
    return num(r.get("psnr_db"))


def sweep_series(rows, experiment_name):
    """Lines of a sweep plot: {(method, group): sorted [(x, row)]}; baselines once."""
    lines = {}
    groups = sorted({r["group"] for r in rows if r["method"] != FULL}, key=_group_key)
    for r in rows:
        m = r["method"]
        if m in (FULL, *EQUAL_TIME_BASELINES) or not math.isfinite(num(r["x"])):
            continue
        if m in BASELINES and groups and r["group"] != groups[0]:
            continue
        key = (m, "" if m in BASELINES else r["group"])
        lines.setdefault(key, []).append((num(r["x"]), r))
    return {k: sorted(v, key=lambda p: p[0]) for k, v in lines.items()}


def _group_key(g: str):
    try:
        return (0, float(g.split("=", 1)[1]))
    except (IndexError, ValueError):
        return (1, g)


def _md_number(value, digits=4) -> str:
    v = num(value)
    if not math.isfinite(v):
        return "-" if math.isnan(v) else _fmt(v)
    return f"{v:.{digits}g}"


def markdown_tables(rows, experiment: Experiment) -> str:
    """The experiment's tables as markdown (no heading, no command)."""
    ok = ok_rows(rows)
    tables = {"tradeoff": _tradeoff_table, "gallery": _gallery_table,
              "denoise": lambda ok, _: denoise_tables(ok)}.get(experiment.kind, _sweep_tables)
    out = tables(ok, experiment)
    failed = [r for r in rows if r.get("status", "ok") != "ok"]
    if failed:
        where = {"gallery": ("group",), "denoise": ("group", "setting", "spp")}.get(
            experiment.kind, ("setting",))
        out.append("")
        out.append("Failed runs: " + "; ".join(
            f"{r['method']} {' '.join(str(r[w]) for w in where)}: {r['status']}"
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
                                if r["method"] in EQUAL_TIME_BASELINES else "")
        cells = [r["group"], r["method"], label, r["spp"], _md_number(r["total_s"]),
                 _md_number(r["relative_time"], 3), _md_number(r["error"])]
        cells += ([_md_number(r["error_converged"]), _md_number(r["psnr_converged_db"], 4)]
                  if stoch else [_md_number(r["psnr_db"], 4)])
        out.append("| " + " | ".join(str(c) for c in cells) + " |")
    return out


def _sweep_tables(ok, experiment: Experiment) -> list:
    """A table per measure (error, relative time, ...): a row per method, a column per x."""
    out = []
    lines = sweep_series(ok, experiment.name)
    xs = sorted({x for pts in lines.values() for x, _ in pts})
    head = "| method | " + " | ".join(f"{x:g}" for x in xs) + " |"
    sep = "| --- |" + " ---: |" * len(xs)
    full = {}
    for r in ok:
        if r["method"] == FULL and math.isfinite(num(r["x"])):
            full[num(r["x"])] = r
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
            by_x = {x: dict(r, relative_min=num(r.get("total_min_s")) / num(
                (full.get(x) or {}).get("total_min_s"))) for x, r in pts}
            label = method if not group else f"{method} {group}"
            out.append(f"| {label} | " + " | ".join(
                _md_number(by_x[x][column], digits) if x in by_x else "-" for x in xs) + " |")
        if column == "total_s" and full:
            out.append("| full | " + " | ".join(
                _md_number(full[x]["total_s"], digits) if x in full else "-" for x in xs)
                + " |")
        out.append("")
    warm = [r for r in ok if r["method"] not in EQUAL_TIME_BASELINES]
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
                                if r["method"] in EQUAL_TIME_BASELINES else "")
        cells = [r["group"], method, r["spp"], _md_number(r["relative_time"], 3),
                 _md_number(error_of(r)), _md_number(_psnr_of(r), 4),
                 _md_number(r.get("min_value"), 3)]
        out.append("| " + " | ".join(str(c) for c in cells) + " |")
    negative = []
    for scene in dict.fromkeys(r["group"] for r in ok):
        rows = [r for r in ok if r["group"] == scene]
        full = [r for r in rows if r["method"] == FULL]
        if not full or not num(full[0].get("min_value")) >= 0:
            continue
        below = [f"{r['method']} ({_md_number(r['min_value'], 3)})" for r in rows
                 if r["method"] not in (FULL, *EQUAL_TIME_BASELINES)
                 and num(r.get("min_value")) < 0]
        if below:
            negative.append(f"{scene}: " + ", ".join(below))
    out += ["", "Pixels below 0 where the full render has none: "
            + ("; ".join(negative) if negative else "none") + "."]
    return out


def environment_line(env: dict) -> str:
    return (f"{env['variant']}, Mitsuba {env['mitsuba']}, Dr.Jit {env['drjit']}, "
            f"{env['cpu_count']} CPUs ({env['cpu_model']}, {env['machine']}), "
            f"{env['platform']}, Python {env['python']}")


# --------------------------------------------------------------------------- denoise

#: The targets of issue 15: (a) equal time up to this fraction of the full render;
#: (b) equal error within these fractions (Fig. 1 scene, gallery); (c) the
#: ``denoise`` stage within this fraction at 400 x 400.
EQUAL_TIME_UP_TO = 0.25
EQUAL_ERROR_TARGETS = {"paper_fig1": 0.05, "gallery": 0.10}
DENOISE_STAGE_TARGET = 0.05


#: The label of the default sample fraction in the denoise experiment's settings.
_DEFAULT_FRACTION = f"f={MRTParams().sample_fraction:g}"


def _is_oidn(method: str) -> bool:
    return method in (OIDN, OIDN_NOAUX)


def is_mrt(method: str) -> bool:
    return method.startswith("mrt-")


def _curve_label(method: str, setting: str) -> str:
    """A curve's name: the method, with OIDN's quality (``oidn fast``) or the MRT's
    sample fraction where it is not the default (``mrt-fast f=0.05``)."""
    if _is_oidn(method):
        return f"{method} {setting.split('=', 1)[-1]}"
    fraction = setting.split(",", 1)[0]
    if is_mrt(method) and fraction.startswith("f=") and fraction != _DEFAULT_FRACTION:
        return f"{method} {fraction}"
    return method


def denoise_curves(rows) -> dict:
    """{scene group: {curve label: [(relative time, error, row)] by spp}} of the ok rows."""
    out = {}
    for r in ok_rows(rows):
        t, e = num(r["relative_time"]), num(r["error_converged"])
        if not (math.isfinite(t) and math.isfinite(e)):
            continue
        group = _scene_of(r)
        label = _curve_label(r["method"], r["setting"])
        out.setdefault(group, {}).setdefault(label, []).append((t, e, r))
    for curves in out.values():
        for pts in curves.values():
            pts.sort(key=lambda p: int(num(p[2]["spp"])))
    return out


def reference_error(curves: dict) -> tuple[float, float]:
    """(error, seconds) of the full render at the top of the ladder."""
    full = curves.get(FULL, [])
    if not full:
        return math.nan, math.nan
    top = full[-1][2]
    return num(top["error_converged"]), num(top["total_s"]) / num(top["relative_time"])


def time_to_reach(points, target: float) -> tuple[float, str]:
    """Relative time at which a curve's error first falls to ``target``: (time, how).

    ``how`` is ``""`` (interpolated, log error against log time, between the
    last point above the target and the first at or below it), ``"<="`` (its
    cheapest point is already there: an upper bound) or ``"not reached"``
    (time nan).
    """
    previous = None
    for t, e, _ in points:
        if e <= target:
            if previous is None:
                return t, "<="
            t0, e0 = previous
            if e <= 0 or e0 <= e or t0 <= 0 or t <= 0:
                return t, ""
            w = (math.log(e0) - math.log(target)) / (math.log(e0) - math.log(e))
            return math.exp(math.log(t0) + w * (math.log(t) - math.log(t0))), ""
        previous = (t, e)
    return math.nan, "not reached"


def _frontier(points, t: float) -> float:
    """The lowest error of ``points`` within time budget ``t`` (inf: none fits)."""
    return min((e for pt, e, _ in points if pt <= t), default=math.inf)


def equal_time_verdict(curves: dict, up_to: float = EQUAL_TIME_UP_TO) -> dict:
    """Target (a): the best MRT against the best OIDN within every time budget up to ``up_to``.

    At each budget (every measured time up to ``up_to``, and ``up_to``), the
    lowest error any MRT configuration reaches within it against the lowest
    any ``oidn`` configuration does. Returns ``holds``, ``worst`` (the
    largest MRT / OIDN error ratio, inf where only OIDN fits), ``at`` (its
    budget) and ``least_gain`` (the smallest OIDN / MRT error ratio where
    both fit). Where no MRT run fits within ``up_to`` it does not hold.
    """
    mrt = [p for label, pts in curves.items() if is_mrt(label) for p in pts]
    oidn = [p for label, pts in curves.items() if label.split()[0] in (OIDN, OIDN_NOAUX)
            for p in pts]
    budgets = sorted({t for t, _, _ in mrt + oidn if t <= up_to} | {up_to})
    worst, at, least_gain = 0.0, math.nan, math.inf
    if math.isinf(_frontier(mrt, up_to)):  # no MRT run fits: nothing to compare
        return {"holds": False, "worst": math.inf, "at": up_to, "least_gain": math.nan}
    for t in budgets:
        em, eo = _frontier(mrt, t), _frontier(oidn, t)
        if math.isinf(em) and math.isinf(eo):
            continue
        ratio = em / eo if math.isfinite(eo) else 0.0
        if ratio > worst:
            worst, at = ratio, t
        if math.isfinite(em) and math.isfinite(eo):
            least_gain = min(least_gain, eo / em)
    return {"holds": worst < 1.0, "worst": worst, "at": at, "least_gain": least_gain}


def _best(curves: dict, target: float, which) -> tuple[str, float, str]:
    """(label, relative time, how) of the curve among ``which`` that reaches ``target`` first."""
    best = ("-", math.nan, "not reached")
    for label, pts in curves.items():
        if not which(label):
            continue
        t, how = time_to_reach(pts, target)
        if math.isfinite(t) and not t >= num(best[1]):
            best = (label, t, how)
    return best


def _fmt_reach(t: float, how: str) -> str:
    if how == "not reached":
        return "not reached"
    return ("<= " if how == "<=" else "") + _md_number(t, 3)


def _scene_of(r) -> str:
    return r.get("group") or r["scene"].rsplit("/", 1)[-1].removesuffix(".xml")


def noise_floors(rows) -> dict:
    """{scene: {MRT method: error}} of the rows of a noise-free trace."""
    out = {}
    for r in ok_rows(rows):
        if r["setting"] == NOISE_FREE and math.isfinite(num(r["error_converged"])):
            out.setdefault(_scene_of(r), {})[r["method"]] = num(r["error_converged"])
    return out


def denoise_summary(rows) -> list:
    """Per scene: the full render, the targets (a) and (b), how each is met, and the
    lowest error of an MRT mode on a noise-free trace (``floor``: (method, error))."""
    out = []
    floors = noise_floors(rows)
    for group, curves in denoise_curves(rows).items():
        e64, t64 = reference_error(curves)
        a = equal_time_verdict(curves)
        mrt = _best(curves, e64, is_mrt)
        oidn = _best(curves, e64, lambda label: label.split()[0] in (OIDN, OIDN_NOAUX))
        target = EQUAL_ERROR_TARGETS["paper_fig1" if group == "paper_fig1" else "gallery"]
        floor = min(floors.get(group, {}).items(), key=lambda kv: kv[1],
                    default=("-", math.nan))
        out.append({"scene": group, "full_s": t64, "full_error": e64, "a": a,
                    "mrt": mrt, "oidn": oidn, "b_target": target, "floor": floor,
                    "b_holds": math.isfinite(mrt[1]) and mrt[1] <= target})
    return out


def _denoise_stage(rows) -> dict:
    """{scene: (median, largest) of the MRT's ``denoise`` stage, relative to the full render}."""
    out = {}
    for group, curves in denoise_curves(rows).items():
        _, t64 = reference_error(curves)
        stages = [num(r.get("denoise_s")) / t64 for label, pts in curves.items()
                  if is_mrt(label) and denoised_mode(label)[1] for _, _, r in pts]
        stages = [s for s in stages if math.isfinite(s)]
        if stages:
            out[group] = (float(np.median(stages)), max(stages))
    return out


def _ladders(rows) -> dict:
    """{scene: its sampler and spp ladder}, from the full render's rows."""
    out = {}
    for group, curves in denoise_curves(rows).items():
        full = [p[2] for p in curves.get(FULL, [])]
        if full:
            sampler = full[0].get("sampler") or full[0]["setting"].split("=", 1)[-1]
            out[group] = (f"sampler `{sampler}`, spp " + ", ".join(str(r["spp"]) for r in full))
    return out


def denoise_tables(rows) -> list:
    """The denoise experiment's markdown: summary (and each scene's sampler and
    ladder), equal error, equal time."""
    notes = _ladders(rows)
    summary = denoise_summary(rows)
    stage = _denoise_stage(rows)
    out = ["Errors: the report's metric against the converged reference (the mean of "
           f"{CONVERGED_FACTOR} full renders at the top spp, other seeds); times: median "
           "totals, relative to the full render at the top of the ladder (`full s`). "
           "(a) equal time: the lowest error any MRT configuration reaches within a time "
           f"budget against the lowest any `oidn` does, at every budget up to "
           f"{EQUAL_TIME_UP_TO:g}; *worst* is the largest MRT / OIDN error ratio (below 1: "
           "the MRT is better everywhere), *gain* the smallest OIDN / MRT ratio. "
           "(b) equal error: the relative time a method needs to reach the full render's "
           "own error (interpolated on its ladder, log-log; `<=`: already at its cheapest "
           "spp). `denoise` stage: median (largest) over the MRT's runs with it. "
           "Noise-free MRT: the lowest error of an MRT mode whose traced values are all the "
           "converged reference's (no time): what its reconstruction alone leaves, which no "
           "denoising of the traced pixels removes.", "",
           "| scene | full s | full error | (a) worst MRT/OIDN | (a) gain | best MRT at "
           "equal error | relative time | best OIDN at equal error | relative time | (b) "
           "target | `denoise` stage / full | noise-free MRT |",
           "| --- | ---: | ---: | ---: | ---: | --- | ---: | --- | ---: | --- | ---: | --- |"]
    for s in summary:
        a = s["a"]
        verdict_a = ("**met**" if a["holds"] else "**not met**") + f" {_md_number(a['worst'], 3)}"
        if not a["holds"] and math.isfinite(a["at"]):
            verdict_a += f" at {_md_number(a['at'], 3)}"
        verdict_b = ("**met**" if s["b_holds"] else "**not met**") + f" (<= {s['b_target']:g})"
        dn = stage.get(s["scene"])
        out.append("| " + " | ".join([
            s["scene"], _md_number(s["full_s"], 3), _md_number(s["full_error"]), verdict_a,
            _md_number(a["least_gain"], 3), s["mrt"][0], _fmt_reach(*s["mrt"][1:]),
            s["oidn"][0], _fmt_reach(*s["oidn"][1:]), verdict_b,
            f"{_md_number(dn[0], 3)} ({_md_number(dn[1], 3)})" if dn else "-",
            f"{_md_number(s['floor'][1])} ({s['floor'][0]})"]) + " |")
    if notes:
        out += [""] + [f"- {scene}: {line}" for scene, line in notes.items()]

    out += ["", "### Equal error", "",
            "Relative time each method needs to reach the full render's own error; the "
            "MRT modes' error on a noise-free trace beside.", "",
            "| scene | method | relative time | its error at its top spp | noise-free |",
            "| --- | --- | ---: | ---: | ---: |"]
    floors = noise_floors(rows)
    for group, curves in denoise_curves(rows).items():
        e64, _ = reference_error(curves)
        for label, pts in curves.items():
            t, how = time_to_reach(pts, e64)
            floor = floors.get(group, {}).get(label)
            out.append(f"| {group} | {label} | {_fmt_reach(t, how)} | "
                       f"{_md_number(pts[-1][1])} | "
                       f"{'-' if floor is None else _md_number(floor)} |")

    out += ["", "### Equal time", "",
            "At each MRT configuration's time: the `oidn` configuration (method, quality, "
            "spp) whose time is closest (log scale) and error lowest.", "",
            "| scene | method | spp | relative time | error | best OIDN there | its relative "
            "time | its error | MRT / OIDN error |",
            "| --- | --- | ---: | ---: | ---: | --- | ---: | ---: | ---: |"]
    for group, curves in denoise_curves(rows).items():
        oidn = {label: pts for label, pts in curves.items()
                if label.split()[0] in (OIDN, OIDN_NOAUX)}
        for label, pts in curves.items():
            if not is_mrt(label):
                continue
            for t, e, r in pts:
                near = [min(p, key=lambda q: abs(math.log(q[0] / t))) + (name,)
                        for name, p in oidn.items() if p]
                if not near:
                    continue
                ot, oe, orow, name = min(near, key=lambda q: q[1])
                out.append(f"| {group} | {label} | {r['spp']} | {_md_number(t, 3)} | "
                           f"{_md_number(e)} | {name}, {orow['spp']} spp | "
                           f"{_md_number(ot, 3)} | {_md_number(oe)} | "
                           f"{_md_number(e / oe, 3)} |")
    return out

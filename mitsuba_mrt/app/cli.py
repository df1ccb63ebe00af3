"""``python -m mitsuba_mrt``: argument parsing only; the work is in the library.

The commands own their process, so they opt into the process tuning of
:func:`mitsuba_mrt.runtime.configure` before any work.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import warnings

from ..errors import MRTError, MRTWarning, first_line, one_line
from ..renderer.variants import VARIANT_CHOICES
from ..types import DENOISE_QUALITIES, DENOISERS


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


def _define(text: str) -> tuple[str, str]:
    name, sep, value = text.partition("=")
    if not sep or not name.strip():
        raise argparse.ArgumentTypeError(f"-D expects name=value, got {text!r}")
    return name.strip(), value


#: The MRT parameters as options: (field of MRTParams, type, help).
_PARAM_OPTIONS = (
    ("sample_fraction", float, "fraction of pixels traced, in (0, 1]"),
    ("filter_sigma", float, "sigma of the Gaussian id smoothing, pixels"),
    ("filter_cutoff", float, "normalised cutoff of the id smoothing"),
    ("max_inpoints", int, "most RBF centres per id"),
    ("num_cappoints", int, "brightest and darkest capstones per id"),
    ("noise_smoothing", float, "in fast, refine and idpass, average traced grid values "
                               "that agree within this many noise sigmas; 0: off"),
    ("time_limit", float, "mode auto: seconds the whole render may take; denoised "
                          "passes fill them"),
    ("noise_threshold", float, "mode auto: the largest estimated relative RMS error "
                               "accepted; the passes end when they meet it (default: a full "
                               "render's own noise at the scene's spp)"),
)


def _add_mrt_options(parser: argparse.ArgumentParser) -> None:
    from ..types import MRTParams

    d = MRTParams()
    g = parser.add_argument_group(
        "MRT parameters (the report's names; default: the scene's mrt integrator's, "
        "else the value shown)")
    for name, kind, text in _PARAM_OPTIONS:
        g.add_argument("--" + name.replace("_", "-"), type=kind, default=None,
                       help=f"{text} ({getattr(d, name) if getattr(d, name) is not None else 'none'})")
    g.add_argument("--id-rule", choices=("auto", "paper", "exact"), default=None,
                   help="paper: shape + 0.5 per blocked light; exact: never collides; "
                        "auto: paper in mode paper, exact elsewhere (auto)")
    g.add_argument("--rbf-degree", type=int, choices=(-1, 0, 1), default=None,
                   help="polynomial added to the linear RBF; -1 is the report's (-1)")
    g.add_argument("--denoise", choices=DENOISERS, default=None,
                   help="denoise the traced grid before reconstructing it (and refine's "
                        "whole image after); oidn: Intel Open Image Denoise "
                        "(pip install mitsuba-mrt[denoise]) (none)")
    g.add_argument("--denoise-quality", choices=DENOISE_QUALITIES, default=None,
                   help="OIDN's quality preset with --denoise oidn; auto: high on the grid, "
                        "fast on whole images, but auto's passes end with high where "
                        "it pays (auto)")


def _add_render_options(parser: argparse.ArgumentParser, batch: bool = False) -> None:
    """The options of a render job, shared by ``render`` and ``batch``."""
    if batch:
        parser.add_argument("-D", dest="defines", action="append", type=_define, default=[],
                            metavar="NAME=VALUES",
                            help="set a scene <default> parameter: a value, a comma list "
                                 "(res=200,400) or a range start:stop:step, stop exclusive "
                                 "(azimuth=0:360:15); several -D make every combination")
    else:
        parser.add_argument("-D", dest="defines", action="append", type=_define, default=[],
                            metavar="NAME=VALUE", help="set a scene <default> parameter")
    parser.add_argument("--spp", type=int, default=None,
                        help="samples per traced pixel (default: the scene's sampler)")
    parser.add_argument("--seed", type=int, default=0, help="sampler seed (default 0)")
    parser.add_argument("--sensor", type=int, default=0,
                        help="index of the scene's sensor to render (default 0); outputs of "
                             "sensor N > 0 are named <scene>_sensorN")
    parser.add_argument("--variant", choices=VARIANT_CHOICES, default="auto",
                        help="Mitsuba variant; auto: LLVM if libLLVM >= 17, else scalar")
    parser.add_argument("--no-reference", action="store_true",
                        help="skip the full reference render (no error, no PSNR)")
    parser.add_argument("--json", action="store_true",
                        help="print the JSON summary" + (" of every task" if batch else ""))
    parser.add_argument("--mode", default=None, metavar="MODE",
                        help="reconstruction mode: " + ", ".join(_modes())
                             + "; auto: the image in denoised passes until --noise-threshold "
                               "or --time-limit, or a full render where nothing is to gain "
                               "(default: the scene's mrt integrator's mode, else auto)")
    _add_mrt_options(parser)


def _modes() -> list[str]:
    from ..modes import render_modes

    return list(render_modes())


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="python -m mitsuba_mrt",
                     description="The modified ray-tracer (MRT) on Mitsuba 3.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    r = sub.add_parser("render", help="MRT render of a scene, with the full reference")
    r.add_argument("scene", help="Mitsuba XML scene file")
    r.add_argument("-o", "--output", default="out", help="output folder (default %(default)s)")
    r.add_argument("--no-progress", action="store_true",
                   help="no progress bar (it shows on a terminal after 2 s)")
    _add_render_options(r)

    s = sub.add_parser("batch", help="render every scene x every combination of -D values "
                       "on a Dask cluster, a folder each, with a table (needs the batch extra)")
    s.add_argument("scenes", nargs="+", metavar="SCENE", help="Mitsuba XML scene files")
    s.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="output folder: OUT/<scene>_<name>=<value>.../ per task, "
                        "OUT/batch.csv, OUT/<scene>.gif when one parameter varies")
    _add_render_options(s, batch=True)
    s.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="a running Dask scheduler (tcp://host:8786); default: a local "
                        "cluster on this machine")
    s.add_argument("--workers", type=int, default=None, metavar="N",
                   help="worker processes of the local cluster (default: one per core)")
    s.add_argument("--no-progress", action="store_true", help="no progress bar")

    from ..bench import EXPERIMENTS

    b = sub.add_parser("bench", help="the report's experiments: MRT against the full render "
                       "and the baselines (CSV, plots, markdown tables)")
    b.add_argument("experiment", choices=(*EXPERIMENTS, "rival", "all"),
                   help="which experiment (gallery: every mode on the ordinary scenes of "
                        "scenes_xml/gallery; rival: auto against full renders denoised with "
                        "OIDN; all: every one but rival, into the same folder)")
    b.add_argument("-o", "--output", default="out/bench",
                   help="output folder (default %(default)s)")
    b.add_argument("--quick", action="store_true",
                   help="a reduced sweep at low resolution, repeats 1 (for tests)")
    b.add_argument("--repeats", type=int, default=None,
                   help="timed runs of every method per point, median reported "
                        "(default 3; 1 with --quick)")
    b.add_argument("--variant", choices=VARIANT_CHOICES, default="auto",
                   help="Mitsuba variant; auto: LLVM if libLLVM >= 17, else scalar")
    b.add_argument("--methods", default=None, metavar="A,B,...",
                   help="comma list of methods (full, mrt-<mode>, nearest, bicubic); "
                        "default: full and every mode but auto (gallery: auto, paper, fast, "
                        "refine, idpass and bicubic); full always runs")
    b.add_argument("--res", type=int, default=None,
                   help="image side for every experiment but pixels "
                        "(default 200, tradeoff 400, gallery 128; --quick 64, gallery 32)")
    b.add_argument("--scenes", default=None, metavar="DIR",
                   help="folder of the report's scenes (default: the repository's scenes_xml)")
    b.add_argument("--truth-spp", type=int, default=None, metavar="N",
                   help="rival: spp of the converged renders errors are measured against, "
                        "a multiple of 128 (default 4096; kept in OUTPUT/cache)")
    b.add_argument("--no-oidn", action="store_true",
                   help="rival: as without Intel Open Image Denoise installed (the "
                        "alternative: the full render at fewer spp)")
    b.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="measure the points on the Dask cluster of this scheduler "
                        "(tcp://host:8786), a point's methods all on one worker "
                        "(needs the batch extra); default: in this process")
    b.add_argument("--workers", type=int, default=None, metavar="N",
                   help="measure the points on a local Dask cluster of N worker processes")
    b.add_argument("--no-progress", action="store_true", help="no progress bar")
    return parser


def _param_overrides(args) -> dict:
    """The MRT parameters given on the command line (None: not given)."""
    names = [name for name, _, _ in _PARAM_OPTIONS] + ["id_rule", "rbf_degree", "denoise",
                                                       "denoise_quality"]
    return {name: getattr(args, name) for name in names if getattr(args, name) is not None}


def _job_options(args) -> dict:
    """The fields of a RenderJob beyond scene, folder and defines."""
    return dict(param_overrides=_param_overrides(args), spp=args.spp, seed=args.seed,
                variant=args.variant, reference=not args.no_reference, mode=args.mode,
                sensor=args.sensor)


def _render(args) -> int:
    from .job import RenderJob, run_render_job, summary_line

    job = RenderJob(scene=args.scene, out_dir=args.output, defines=dict(args.defines),
                    progress=not args.no_progress, **_job_options(args))
    summary = run_render_job(job)
    print(json.dumps(summary.as_dict(), indent=2) if args.json else summary_line(summary))
    for note in (summary.auto or {}).get("notes", []):  # what the plan wants a user to know
        print(f"note: {note}", file=sys.stderr)
    return 0


def _batch(args) -> int:
    from .batch import run_batch

    result = run_batch(args.scenes, args.output, args.defines, scheduler=args.scheduler,
                       workers=args.workers, progress=not args.no_progress,
                       echo=(lambda line: print(line, file=sys.stderr)) if args.json else print,
                       **_job_options(args))
    if args.json:
        print(json.dumps(result.rows, indent=2))
    else:
        done = len(result.rows) - result.failed - result.count("skipped")
        print(f"batch: {done} rendered, {result.count('skipped')} skipped, "
              f"{result.failed} failed; table {result.table}")
        for gif in result.animations:
            print(f"animation {gif}")
    for note in result.notes:
        print(note, file=sys.stderr)
    if result.failed:
        print(f"error: {result.failed} of {len(result.rows)} tasks failed "
              f"(messages in {result.table})", file=sys.stderr)
        return 1
    return 0


def _bench(args) -> int:
    import shlex

    from ..bench import run_experiment, summary_line

    command = "python -m mitsuba_mrt " + shlex.join(args.argv)
    # a benchmark plans from what its own process measures, not from what the
    # user's earlier renders remembered (runtime.memory), unless told to
    os.environ.setdefault("MITSUBA_MRT_MEMORY", "off")
    if args.experiment == "rival":
        return _rival(args, command)
    if args.no_oidn:
        raise MRTError("--no-oidn is an option of bench rival")
    with contextlib.ExitStack() as stack:
        map_points = None
        if args.scheduler or args.workers is not None:
            from .cluster import cluster_map

            map_points = stack.enter_context(cluster_map(
                args.scheduler, args.workers, lambda line: print(line, file=sys.stderr)))
        results = run_experiment(args.experiment, args.output, quick=args.quick,
                                 repeats=args.repeats, variant=args.variant,
                                 methods=args.methods, res=args.res, scenes_dir=args.scenes,
                                 progress=not args.no_progress, command=command,
                                 map_points=map_points)
    for name, result in results.items():
        print(summary_line(name, result))
    return 0


def _rival(args, command: str) -> int:
    from pathlib import Path

    from ..bench.experiments import GALLERY_SCENES, check_res, gallery_defines
    from ..bench.rival import CONVERGED_SPP, FIG1_DEFINES, check_truth_spp, run_rival
    from ..renderer.variants import activate

    truth_spp = CONVERGED_SPP if args.truth_spp is None else check_truth_spp(args.truth_spp)
    activate(args.variant)
    root = Path(args.scenes) if args.scenes else Path(__file__).resolve().parents[2] / "scenes_xml"
    res = check_res(args.res) if args.res is not None else (64 if args.quick else 256)
    scenes = [(root / "gallery" / f"{name}.xml", name, gallery_defines(name, res))
              for name in (GALLERY_SCENES[:2] if args.quick else GALLERY_SCENES)]
    scenes.append((root / "paper_fig1.xml", "paper_fig1",
                   {**FIG1_DEFINES, **({"res": 64} if args.quick else {})}))
    repeats = (1 if args.quick else 2) if args.repeats is None else args.repeats
    table = run_rival(args.output, scenes, repeats=repeats, quick=args.quick, command=command,
                      truth_spp=truth_spp, oidn=not args.no_oidn,
                      echo=lambda line: print(line, file=sys.stderr))
    print(f"rival: table {table}")
    return 0


def unsupported_by_mitsuba(exc: BaseException) -> bool:
    """Whether ``exc`` is Mitsuba saying that a plugin of the scene lacks what
    another asks of it ("Texture::eval_1_grad(): not implemented!" for a bump
    map over a checkerboard): the scene is at fault, and ``mi.render`` fails
    on it alike.

    Examples
    --------
    >>> unsupported_by_mitsuba(RuntimeError("[Texture] Texture::eval_1_grad(): not implemented!"))
    True
    >>> unsupported_by_mitsuba(RuntimeError("out of memory"))
    False
    """
    return isinstance(exc, RuntimeError) and "(): not implemented" in str(exc)


def innermost(exc: BaseException) -> BaseException:
    """The exception at the bottom of ``exc``'s chain of causes (Dr.Jit wraps
    the real error of a custom operation, e.g. Mitsuba's render, in a
    RuntimeError that says "see above")."""
    seen = {id(exc)}
    while True:
        inner = exc.__cause__ or (None if exc.__suppress_context__ else exc.__context__)
        if inner is None or id(inner) in seen:
            return exc
        seen.add(id(inner))
        exc = inner


def _show_warning(message, category, filename, lineno, file=None, line=None,
                  _default=warnings.showwarning):
    """Our warnings as one ``warning:`` line; others as Python prints them."""
    if issubclass(category, MRTWarning):
        print(f"warning: {message}", file=sys.stderr)
    else:
        _default(message, category, filename, lineno, file, line)


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(argv)
    args.argv = argv
    from ..runtime import configure

    configure()
    warnings.showwarning = _show_warning
    try:
        return {"render": _render, "batch": _batch, "bench": _bench}[args.command](args)
    except MRTError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - never a traceback on the terminal
        cause = innermost(exc)
        if unsupported_by_mitsuba(cause):  # bad input: a scene Mitsuba cannot render
            print(f"error: Mitsuba cannot render this scene: {first_line(cause)}", file=sys.stderr)
            return 2
        print(f"error: {one_line(cause)}", file=sys.stderr)
        return 2 if isinstance(cause, MRTError) else 1

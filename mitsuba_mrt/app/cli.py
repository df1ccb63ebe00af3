"""``python -m mitsuba_mrt``: argument parsing only; the work is in the library."""

from __future__ import annotations

import argparse
import json
import sys

from .errors import MRTError
from .variants import VARIANT_CHOICES


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


def _define(text: str) -> tuple[str, str]:
    name, sep, value = text.partition("=")
    if not sep or not name.strip():
        raise argparse.ArgumentTypeError(f"-D expects name=value, got {text!r}")
    return name.strip(), value


def _add_mrt_options(parser: argparse.ArgumentParser) -> None:
    from .pipeline import MRTParams

    d = MRTParams()
    g = parser.add_argument_group("MRT parameters (the report's names)")
    g.add_argument("--sample-fraction", type=float, default=d.sample_fraction,
                   help="fraction of pixels traced, in (0, 1] (default %(default)s)")
    g.add_argument("--filter-sigma", type=float, default=d.filter_sigma,
                   help="sigma of the Gaussian id smoothing, pixels (default %(default)s)")
    g.add_argument("--filter-cutoff", type=float, default=d.filter_cutoff,
                   help="normalised cutoff of the id smoothing (default %(default)s)")
    g.add_argument("--max-inpoints", type=int, default=d.max_inpoints,
                   help="most RBF centres per id (default %(default)s)")
    g.add_argument("--num-cappoints", type=int, default=d.num_cappoints,
                   help="brightest and darkest capstones per id (default %(default)s)")
    g.add_argument("--id-rule", choices=("auto", "paper", "exact"), default=d.id_rule,
                   help="paper: shape + 0.5 per blocked light; exact: never collides; "
                        "auto (default): paper in mode paper, exact elsewhere")
    g.add_argument("--rbf-degree", type=int, choices=(-1, 0, 1), default=d.rbf_degree,
                   help="polynomial added to the linear RBF; -1 is the report's")


def _modes() -> list[str]:
    from . import MODES

    return ["auto"] + list(MODES)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="python -m mitsuba_mrt",
                     description="The modified ray-tracer (MRT) on Mitsuba 3.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    r = sub.add_parser("render", help="MRT render of a scene, with the full reference")
    r.add_argument("scene", help="Mitsuba XML scene file")
    r.add_argument("-o", "--output", default="out", help="output folder (default %(default)s)")
    r.add_argument("-D", dest="defines", action="append", type=_define, default=[],
                   metavar="NAME=VALUE", help="set a scene <default> parameter")
    r.add_argument("--spp", type=int, default=None,
                   help="samples per traced pixel (default: the scene's sampler)")
    r.add_argument("--seed", type=int, default=0, help="sampler seed (default 0)")
    r.add_argument("--variant", choices=VARIANT_CHOICES, default="auto",
                   help="Mitsuba variant; auto: LLVM if libLLVM >= 17, else scalar")
    r.add_argument("--no-reference", action="store_true",
                   help="skip the full reference render (no error, no PSNR)")
    r.add_argument("--json", action="store_true", help="print the JSON summary")
    r.add_argument("--mode", default="auto", metavar="MODE",
                   help="reconstruction mode: " + ", ".join(_modes())
                        + "; auto: fast when a measured pilot says it beats a full render, "
                          "else the full render (default %(default)s)")
    _add_mrt_options(r)

    from .bench import EXPERIMENTS

    b = sub.add_parser("bench", help="the report's experiments: MRT against the full render "
                       "and the baselines (CSV, plots, markdown tables)")
    b.add_argument("experiment", choices=(*EXPERIMENTS, "all"),
                   help="which experiment (all: every one, into the same folder)")
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
                        "default: full and every mode; full always runs")
    b.add_argument("--res", type=int, default=None,
                   help="image side for every experiment but pixels "
                        "(default 200, tradeoff 400; --quick 64)")
    b.add_argument("--scenes", default=None, metavar="DIR",
                   help="folder of the report's scenes (default: the repository's scenes_xml)")
    b.add_argument("--no-progress", action="store_true", help="no progress bar")
    return parser


def _params(args):
    from .pipeline import MRTParams

    return MRTParams(sample_fraction=args.sample_fraction, filter_sigma=args.filter_sigma,
                     filter_cutoff=args.filter_cutoff, max_inpoints=args.max_inpoints,
                     num_cappoints=args.num_cappoints, id_rule=args.id_rule,
                     rbf_degree=args.rbf_degree)


def _render(args) -> int:
    from .job import RenderJob, run_render_job, summary_line

    if args.spp is not None and args.spp < 1:
        raise MRTError(f"--spp must be >= 1, got {args.spp}")
    if args.mode not in _modes():
        raise MRTError(f"unknown mode {args.mode!r}; choose one of {', '.join(_modes())}")
    job = RenderJob(scene=args.scene, out_dir=args.output, defines=dict(args.defines),
                    params=_params(args), spp=args.spp, seed=args.seed,
                    variant=args.variant, reference=not args.no_reference, mode=args.mode)
    summary = run_render_job(job)
    print(json.dumps(summary, indent=2) if args.json else summary_line(summary))
    return 0


def _bench(args) -> int:
    import shlex

    from .bench import run_experiment, summary_line

    if args.repeats is not None and args.repeats < 1:
        raise MRTError(f"--repeats must be >= 1, got {args.repeats}")
    command = "python -m mitsuba_mrt " + shlex.join(args.argv)
    results = run_experiment(args.experiment, args.output, quick=args.quick,
                             repeats=args.repeats, variant=args.variant, methods=args.methods,
                             res=args.res, scenes_dir=args.scenes,
                             progress=not args.no_progress, command=command)
    for name, result in results.items():
        print(summary_line(name, result))
    return 0


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(argv)
    args.argv = argv
    try:
        return {"render": _render, "bench": _bench}[args.command](args)
    except MRTError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - never a traceback on the terminal
        message = str(exc).strip().splitlines()
        print(f"error: {type(exc).__name__}: {message[0] if message else ''}", file=sys.stderr)
        return 1

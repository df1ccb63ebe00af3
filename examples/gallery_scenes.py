"""What the examples measured against ``bench rival``'s converged renders share:
a scene by its gallery name, and the ``--truths`` option naming where those
renders are kept."""

import argparse
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Where ``python -m mitsuba_mrt bench rival -o docs/bench`` keeps its converged renders.
TRUTHS = ROOT / "docs" / "bench" / "cache"


def add_truths(parser) -> None:
    """Add ``--truths`` (a folder; :data:`TRUTHS` by default) to ``parser``."""
    parser.add_argument("--truths", default=str(TRUTHS),
                        help="folder of the converged renders bench rival keeps")


def add_truth_spp(parser) -> None:
    """Add ``--truth-spp`` (the spp of the converged renders in ``--truths``;
    4096 by default), refused as ``bench rival`` refuses it: one line, exit 2."""
    parser.add_argument("--truth-spp", type=_truth_spp, default=4096,
                        help="spp of the converged renders in --truths, a multiple of 128 "
                             "(default 4096)")


def _truth_spp(text: str) -> int:
    from mitsuba_mrt.bench.rival import check_truth_spp

    try:
        return check_truth_spp(int(text))
    except ValueError as error:  # (MRTError is one)
        raise argparse.ArgumentTypeError(
            str(error) if text.strip().lstrip("-").isdigit()
            else f"--truth-spp expects an integer, got {text!r}") from None


def load(name: str, res: int):
    """Gallery scene ``name`` at ``res`` pixels a side (``paper_fig1``: the
    report's Fig. 1 with ``path`` at 64 spp, as ``bench rival`` renders it)."""
    import mitsuba_mrt
    from mitsuba_mrt.bench.experiments import gallery_defines

    if name == "paper_fig1":
        return mitsuba_mrt.load_scene(ROOT / "scenes_xml" / "paper_fig1.xml", res=res,
                                      integrator="path", spp=64, jitter="true")
    return mitsuba_mrt.load_scene(ROOT / "scenes_xml" / "gallery" / f"{name}.xml",
                                  **gallery_defines(name, res))


def with_truths(names, res: int, truths):
    """``(name, scene, converged renders)`` of each gallery scene in ``names``
    at ``res`` a side, the process first set up as the command line sets up
    its own (LLVM where usable); the converged renders are
    :func:`mitsuba_mrt.bench.rival.kept_truth`'s (``film`` and ``box``),
    read from, or kept in, the folder ``truths``."""
    import mitsuba_mrt
    from mitsuba_mrt import runtime
    from mitsuba_mrt.bench.rival import kept_truth

    runtime.configure()
    mitsuba_mrt.activate("auto")
    for name in names:
        scene = load(name, res)
        yield name, scene, kept_truth(scene, name, Path(truths))

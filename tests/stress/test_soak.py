"""A soak: many renders in one process, of mixed sizes, modes and spp.

Threads, Dr.Jit's pool, recorded kernels and the package's caches live for
the whole process; a lost wake-up or a cache that grows without bound shows
only after many renders.  The thorough profile (``MITSUBA_MRT_STRESS=thorough``,
``python3 run.py stress``) renders 200 times, the default profile 12.  A
watchdog ends the process with every thread's traceback if the soak hangs.
"""

from __future__ import annotations

import faulthandler
import os

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba")

import mitsuba_mrt  # noqa: E402

from .stress_support import SOFT as THOROUGH  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
RENDERS = 200 if THOROUGH else 12
#: Seconds after which the soak is taken to hang (its renders take about one).
HANG_S = 1800
MODES = ("fast", "refine", "idpass", "paper", "auto")
SIZES = (16, 40, 96, 160, 256, 320)


def test_many_renders_in_one_process_end_and_stay_finite(variant):
    rng = np.random.default_rng(27)
    scenes = {}
    faulthandler.dump_traceback_later(HANG_S, exit=True)
    try:
        for k in range(RENDERS):
            res = int(rng.choice(SIZES)) if variant != "scalar_rgb" else 16
            path = bool(rng.integers(2))
            key = (res, path)
            if key not in scenes:
                defines = {"res": res, "integrator": "path", "jitter": "true"} if path else {
                    "res": res}
                scenes[key] = mitsuba_mrt.load_scene(
                    os.path.join(ROOT, "scenes_xml", "paper_fig1.xml"), **defines)
            mode = MODES[k % len(MODES)]
            result = mitsuba_mrt.render(scenes[key], mode=mode, spp=int(rng.integers(1, 9)),
                                        seed=k)
            assert result.image.shape == (res, res, 3)
            assert np.isfinite(result.image).all(), (k, res, path, mode)
    finally:
        faulthandler.cancel_dump_traceback_later()

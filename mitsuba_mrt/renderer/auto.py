"""Mode ``auto``: a measured plan over full renders, denoised full renders and the MRT.

:func:`plan` runs the pilot (:mod:`.pilot`) and hands its candidates to
the planner (:func:`mitsuba_mrt.modes.plan.choose`) under the render's
controls: ``noise_threshold`` (default: the full render's own error at the
scene's spp) and ``time_limit`` (the pilot's own time counted against it).
:func:`plan_without_pilot` is the plan where no pilot is worth running.
"""

from __future__ import annotations

import time

import mitsuba as mi

from ..modes.plan import Candidate, Plan, choose
from ..recon.sampling import SamplePattern
from ..types import MRTParams
from .pilot import run_pilot

#: Below this many samples (pixels x spp) ``auto`` renders in full without a
#: pilot: the pilot's own launches would cost more than any plan could save.
AUTO_MIN_SAMPLES = 1 << 21
#: The share of what is left of a time limit after the pilot that the
#: render's predicted time may fill (predictions are a pilot's, not exact).
TIME_MARGIN = 0.9


def plan_without_pilot(width: int, height: int, spp: int, jit: bool,
                       params: MRTParams) -> Plan | None:
    """The plan where no pilot is worth running (a full render), else None.

    The scalar variant traces pixel by pixel in Python while ``mi.render``
    runs Mitsuba's multithreaded C++ loop, so only a full render can win
    there; below ``AUTO_MIN_SAMPLES`` samples the pilot would cost more than
    it could save.
    """
    if jit and width * height * spp >= AUTO_MIN_SAMPLES:
        return None
    reason = ("the scalar variant renders in full" if not jit
              else "too few samples for a pilot to pay")
    return Plan(Candidate("full", "full", spp), reason, time_limit=params.time_limit,
                target_error=params.noise_threshold)


def plan(scene: mi.Scene, pattern: SamplePattern, tracer, params: MRTParams,
         started: float) -> Plan:
    """Measure the candidates with a pilot and choose one.

    ``started`` is the render's ``time.perf_counter()`` at its start: what
    is left of ``params.time_limit`` is counted from it.
    """
    begin = time.perf_counter()
    budget = None
    if params.time_limit is not None:
        budget = max(params.time_limit - (begin - started), 0.0) * TIME_MARGIN
    pilot = run_pilot(scene, pattern, tracer, params, params.noise_threshold, budget)
    now = time.perf_counter()
    target = params.noise_threshold
    if target is None and params.time_limit is None:
        target = pilot.full_error
    if params.time_limit is not None:
        budget = max(params.time_limit - (now - started), 0.0) * TIME_MARGIN
    out = choose(pilot.candidates, target_error=target, time_limit=budget)
    out.time_limit, out.budget_s = params.time_limit, budget
    out.pilot_s, out.pilot_pixels, out.notes = now - begin, pilot.pixels, pilot.notes
    return out

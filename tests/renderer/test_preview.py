"""auto's preview under a time limit."""

import time

import mitsuba as mi

from helpers import ball_scene_xml
from mitsuba_mrt import MRTParams
from mitsuba_mrt.recon.sampling import grid_pattern
from mitsuba_mrt.renderer import auto
from mitsuba_mrt.renderer.api import GridTracer
from mitsuba_mrt.renderer.progressive import LaunchCost


def test_a_sampler_that_bakes_its_spp_is_judged_by_the_spp_it_has_launched(variant,
                                                                           monkeypatch):
    # its passes launch only the spp launched before, however cheap the probe's
    # one sample is: a launch of 16 spp that took 50 s leaves no time for a pass
    scene = mi.load_string(ball_scene_xml(64, spp=16, sampler="stratified"))
    tracer = GridTracer(scene, scene.sensors()[0], scene.integrator(), 16, 0)
    pattern, key = grid_pattern(64, 64, 0.1), ("a test's key",)
    params = MRTParams(time_limit=5.0)
    for bakes in (True, False):
        cost = LaunchCost(spp_compiles=bakes)
        cost.add(16, 50.0, recorded=True)
        monkeypatch.setitem(auto._launch_costs, key, cost)
        outcome, _, _ = auto._preview_first(scene, pattern, tracer, params,
                                            time.perf_counter(), key, [])
        # without baking, the recorded launch tells nothing: the probe's pass fits
        assert (outcome is not None and outcome.plan.choice.mode == "fast") == bakes

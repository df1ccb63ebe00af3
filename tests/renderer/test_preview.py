"""auto's preview: its grid pooled from 1-spp launches while the limit allows."""

import time
from dataclasses import dataclass, field, replace

import mitsuba as mi
import numpy as np

from helpers import ball_scene_xml
from mitsuba_mrt import MRTParams
from mitsuba_mrt.recon.sampling import grid_pattern
from mitsuba_mrt.renderer import auto_limit
from mitsuba_mrt.renderer.api import GridTracer
from mitsuba_mrt.renderer.preview import PREVIEW_MAX_SPP, pooled, preview_grid
from mitsuba_mrt.renderer.launch_cost import LaunchCost
from mitsuba_mrt.types import SeedStream, SparseTrace


def _trace(n: int, value: float, stream: int = 0) -> SparseTrace:
    return SparseTrace(radiance=np.full((n, 3), value), albedo=np.full((n, 3), 0.5),
                       shape_index=np.arange(n), visible_lights=np.zeros(n, np.uint32),
                       num_lights=0, spp=1, seconds=0.001, variance=np.zeros((n, 3)),
                       alpha=np.ones(n), normal=np.full((n, 3), float(stream)))


@dataclass
class _Tracer:
    """Traces every pixel at its stream's number, and remembers each call."""

    spp: int
    calls: list = field(default_factory=list)

    def __call__(self, pixel_xy, *, stream=SeedStream.EDGES, replay=False, **kwargs):
        self.calls.append((int(stream), self.spp, replay))
        return _trace(len(pixel_xy), float(stream), int(stream))


def test_a_preview_pools_1_spp_launches_of_seeds_of_its_own_while_the_limit_allows():
    pattern = grid_pattern(40, 40, 0.1)
    first = _trace(pattern.count, 0.0)
    tracer = _Tracer(spp=64)
    grid = preview_grid(first, pattern, tracer, until=time.perf_counter() + 60.0)
    streams = [SeedStream.PREVIEW + k for k in range(1, PREVIEW_MAX_SPP)]
    assert tracer.calls == [(s, 1, True) for s in streams]
    assert grid.spp == PREVIEW_MAX_SPP
    np.testing.assert_allclose(grid.radiance, np.mean([0.0, *streams]))
    assert (grid.variance > 0).all() and (grid.normal == 0.0).all()  # the first's centres
    # a first launch that took longer than the time left (it recorded its kernels): alone
    tracer = _Tracer(spp=64)
    slow = replace(first, seconds=120.0)
    assert preview_grid(slow, pattern, tracer, until=time.perf_counter() + 60.0) is slow
    assert tracer.calls == []
    # ... unless recording its kernels took that time: the next launches replay them
    grid = preview_grid(slow, pattern, tracer, until=time.perf_counter() + 60.0,
                        recording_s=119.99)
    assert grid.spp == PREVIEW_MAX_SPP
    # no time left: the first launch alone, traced here where not given
    tracer = _Tracer(spp=64)
    alone = preview_grid(None, pattern, tracer, until=time.perf_counter() - 1.0)
    assert tracer.calls == [(SeedStream.GRID, 1, True)] and alone.spp == 1


def test_pooling_one_trace_keeps_it_and_equal_samples_have_no_variance():
    one = _trace(5, 0.25)
    assert pooled([one]) is one
    both = pooled([one, one])
    assert both.spp == 2 and (both.variance == 0.0).all() and both.seconds == 0.002


def test_a_sampler_that_bakes_its_spp_is_judged_by_the_spp_it_has_launched(variant,
                                                                           monkeypatch):
    # its passes launch only the spp launched before, however cheap the probe's
    # one sample is: the probe's pass of 0.2 s is 3.2 s at the 16 spp launched
    scene = mi.load_string(ball_scene_xml(64, spp=16, sampler="stratified"))
    tracer = GridTracer(scene, scene.sensors()[0], scene.integrator(), 16, 0)
    pattern, key = grid_pattern(64, 64, 0.1), ("a test's key",)
    probe = auto_limit._grid_probe(pattern, tracer)
    monkeypatch.setattr(auto_limit, "_grid_probe", lambda *args: probe._replace(
        pass_s=0.2, host=0.0, recorded=False))
    monkeypatch.setitem(auto_limit._probe_recording_s, key, 0.0)
    params = MRTParams(time_limit=1.0)
    for bakes in (True, False):
        cost = LaunchCost(spp_compiles=bakes)
        cost.add(16, 50.0, recorded=True)  # (its time holds its compilation)
        monkeypatch.setitem(auto_limit._launch_costs, key, cost)
        outcome, _, _ = auto_limit.preview_first(scene, pattern, tracer, params,
                                                 time.perf_counter(), key, [])
        # without baking, a pass is the probe's one sample: it fits
        assert (outcome is not None and outcome.plan.choice.mode == "fast") == bakes


def test_the_probe_tells_what_of_it_recorded_its_kernels_which_its_replay_does_not(variant):
    scene = mi.load_string(ball_scene_xml(64))  # (new objects: their first trace records)
    tracer = GridTracer(scene, scene.sensors()[0], scene.integrator(), 16, 0)
    pattern = grid_pattern(64, 64, 0.1)
    first, again = (auto_limit._grid_probe(pattern, tracer) for _ in range(2))
    if first.recorded:  # (a JIT variant: the first probe recorded, the second replays)
        assert 0.0 < first.recording <= first.grid.seconds
        assert not again.recorded and again.recording == 0.0
    else:
        assert first.recording == again.recording == 0.0

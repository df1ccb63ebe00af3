"""Replayed traces (drjit.freeze): the same values as a plainly traced one."""

import mitsuba as mi
import numpy as np
import pytest

import mitsuba_mrt
from mitsuba_mrt import grid_pattern
from mitsuba_mrt.renderer.replay import padded_size, recordings, replaying
from mitsuba_mrt.renderer.lanes import is_jit
from mitsuba_mrt.renderer.trace import trace_pixels
from helpers import ball_scene_xml, small_scene_xml

pytestmark = pytest.mark.skipif(not is_jit(), reason="only JIT variants replay kernels")

PATH_SCENE = small_scene_xml(24, '<integrator type="path"><integer name="max_depth" value="3"/>'
                                 '</integrator>', extra='<emitter type="constant"/>')


MIRROR = ('<shape type="rectangle"><transform name="to_world"><scale value="2"/>'
          '<rotate y="1" angle="60"/><translate x="2.5"/></transform>'
          '<bsdf type="conductor"/></shape>')


def _trace(scene, integrator, xy, replay, seed=3, **kwargs):
    return trace_pixels(scene, scene.sensors()[0], integrator, xy, 4, seed, replay=replay,
                        **kwargs)


def _fields(trace):
    return [trace.radiance, trace.albedo, trace.shape_index, trace.visible_lights,
            trace.variance, trace.alpha, trace.normal]


@pytest.mark.parametrize("box", [False, True], ids=["grid", "every pixel, box"])
def test_one_recording_replays_every_larger_spp(box):
    # (the passes' launches: a recording at 2 spp serves 3, 5 and 9 spp; 1 spp is
    # a recording of its own, where the lanes are as many as the pixels)
    scene = mi.load_string(ball_scene_xml(24))  # (the independent sampler: spp not baked in)
    xy = (np.stack(np.meshgrid(np.arange(24), np.arange(24)), -1).reshape(-1, 2) if box
          else grid_pattern(24, 24, 0.1).pixel_xy)
    integrator = scene.integrator()

    def trace(spp, replay):
        return trace_pixels(scene, scene.sensors()[0], integrator, xy, spp, 5, replay=replay,
                            box=box, ids=not box)
    trace(2, True)
    made = recordings()
    for spp in (3, 5, 9, 2):
        replayed, plain = trace(spp, True), trace(spp, False)
        for a, b in zip(_fields(replayed), _fields(plain)):
            np.testing.assert_array_equal(a, b)
    assert recordings() == made
    trace(1, True)
    assert recordings() == made + 1


@pytest.mark.parametrize("every", [False, True], ids=["grid", "every pixel"])
def test_replayed_trace_equals_plain(every):
    scene = mi.load_string(PATH_SCENE)
    xy = (np.stack(np.meshgrid(np.arange(24), np.arange(24)), -1).reshape(-1, 2) if every
          else grid_pattern(24, 24, 0.1).pixel_xy)
    integrator = scene.integrator()
    plain = _trace(scene, integrator, xy, False)
    for seed in (3, 4, 3):  # records, then replays with new and old seeds
        again = _trace(scene, integrator, xy, True, seed)
        reference = _trace(scene, integrator, xy, False, seed)
        for a, b in zip(_fields(again), _fields(reference)):
            np.testing.assert_array_equal(a, b)
    replayed = _trace(scene, integrator, xy, True)
    for a, b in zip(_fields(replayed), _fields(plain)):
        np.testing.assert_array_equal(a, b)


def test_replay_tells_integrators_apart():
    # Dr.Jit alone would replay one path integrator's kernels for another that
    # differs only in max_depth (a plain C++ member, not a Dr.Jit variable)
    scene = mi.load_string(PATH_SCENE)
    xy = grid_pattern(24, 24, 0.2).pixel_xy
    short, deep = (mi.load_dict({"type": "path", "max_depth": d}) for d in (2, 6))
    for _ in range(3):
        _trace(scene, short, xy, True)
    replayed, plain = _trace(scene, deep, xy, True), _trace(scene, deep, xy, False)
    np.testing.assert_array_equal(replayed.radiance, plain.radiance)
    assert not np.array_equal(plain.radiance, _trace(scene, short, xy, False).radiance)


@pytest.mark.parametrize("every", [False, True], ids=["grid", "every pixel"])
def test_replay_tells_layouts_apart(every):
    # the same pixels and spp traced with other Python values baked into the
    # kernels (filter, albedo, halves): Dr.Jit's own key replayed one
    # layout's recording for another
    scene = mi.load_string(PATH_SCENE)
    integrator = scene.integrator()
    xy = (np.stack(np.meshgrid(np.arange(24), np.arange(24)), -1).reshape(-1, 2) if every
          else grid_pattern(24, 24, 0.2).pixel_xy)
    options = [dict(box=b, albedo=a, halves=h) for b in (False, True) for a in (False, True)
               for h in (False, True)]
    for _ in range(2):
        for kwargs in options:
            replayed = _trace(scene, integrator, xy, True, ids=False, **kwargs)
            plain = _trace(scene, integrator, xy, False, ids=False, **kwargs)
            assert (replayed.odd is None) == (not kwargs["halves"])
            for a, b in zip(_fields(replayed) + [replayed.odd], _fields(plain) + [plain.odd]):
                np.testing.assert_array_equal(a, b)


def test_odd_samples_are_a_half_of_the_pixel():
    # the pixel's mean is that of its even- and odd-numbered samples' means
    scene = mi.load_string(PATH_SCENE)
    xy = np.stack(np.meshgrid(np.arange(24), np.arange(24)), -1).reshape(-1, 2)
    trace = _trace(scene, scene.integrator(), xy, True, box=True, halves=True, aovs=False)
    plain = _trace(scene, scene.integrator(), xy, True, box=True, aovs=False)
    np.testing.assert_allclose(trace.radiance, plain.radiance, rtol=1e-6, atol=1e-7)
    even = 2.0 * trace.radiance - trace.odd  # 4 spp: two of each
    assert np.all(even >= -1e-5) and not np.allclose(even, trace.odd)
    assert trace.odd.mean() == pytest.approx(trace.radiance.mean(), rel=0.2)


def test_replay_sees_a_changed_parameter():
    scene = mi.load_string(PATH_SCENE)
    xy = grid_pattern(24, 24, 0.2).pixel_xy
    integrator = scene.integrator()
    before = [_trace(scene, integrator, xy, True).radiance for _ in range(3)][-1]
    params = mi.traverse(scene)
    key = next(k for k in params.keys() if k.endswith("reflectance.value"))
    params[key] = mi.Color3f(0.05, 0.9, 0.05)
    params.update()
    replayed, plain = _trace(scene, integrator, xy, True), _trace(scene, integrator, xy, False)
    np.testing.assert_array_equal(replayed.radiance, plain.radiance)
    assert not np.array_equal(replayed.radiance, before)


def test_one_id_recording_serves_every_pixel_count():
    # the id kernel's recording is keyed without the count: a set of another
    # size replays it, and must come out as its own plain trace
    from mitsuba_mrt.renderer import ids

    scene = mi.load_string(small_scene_xml(24, extra=MIRROR))
    every = np.stack(np.meshgrid(np.arange(24), np.arange(24)), -1).reshape(-1, 2)
    before = ids._IDS.n_recordings
    for xy in (grid_pattern(24, 24, 0.1).pixel_xy, every, every[::7]):
        replayed = _trace(scene, scene.integrator(), xy, True, radiance=False, albedo=False)
        plain = _trace(scene, scene.integrator(), xy, False, radiance=False, albedo=False)
        for a, b in zip((replayed.path_id, replayed.visible_lights, replayed.normal),
                        (plain.path_id, plain.visible_lights, plain.normal)):
            np.testing.assert_array_equal(a, b)
    assert (plain.path_id != plain.shape_index).any()  # the mirror's chains among them
    assert ids._IDS.n_recordings == before + 1


def test_renders_replay_the_grid():
    scene = mi.load_string(small_scene_xml(24))
    results = [mitsuba_mrt.render(scene, mode="idpass", seed=1) for _ in range(3)]
    for result in results[1:]:
        np.testing.assert_array_equal(result.image, results[0].image)


def test_replaying_false_traces_anew():
    from mitsuba_mrt.renderer import develop
    from mitsuba_mrt.renderer.replay import replaying

    scene = mi.load_string(PATH_SCENE)
    xy = grid_pattern(24, 24, 0.3).pixel_xy
    before = develop._DEVELOP.n_recordings
    with replaying(False):
        _trace(scene, scene.integrator(), xy, True)
    assert develop._DEVELOP.n_recordings == before
    # recorded outside it (the trace, and the albedo of the pixels whose first
    # samples disagreed), then replayed
    _trace(scene, scene.integrator(), xy, True)
    recorded = develop._DEVELOP.n_recordings
    assert recorded > before
    _trace(scene, scene.integrator(), xy, True)
    assert develop._DEVELOP.n_recordings == recorded


def test_each_layout_is_recorded_once():
    # NumPy's buffers are 64-byte aligned or not by chance, and Dr.Jit records a
    # frozen call anew when an input's alignment changes: some renders were
    # recorded again; and the recordings of more layouts than a sweep cycles
    # through (fractions x spp x modes) must all be kept
    scene = mi.load_string(PATH_SCENE)
    layouts = [(f, spp, mode) for f in (0.1, 0.2, 0.3) for spp in (1, 4, 9)
               for mode in ("fast", "idpass")]
    counts = []
    for _ in range(4):
        for f, spp, mode in layouts:
            mitsuba_mrt.render(scene, spp=spp, mode=mode, sample_fraction=f)
        counts.append(recordings())
    assert counts[1:] == counts[:1] * 3


def test_a_padded_trace_equals_the_unpadded_one():
    # refine's edge sets change size each render: padded to a few sizes, they
    # replay one recording; Mitsuba's samplers seed each sample by its index,
    # so the pixels' values are those traced without padding

    scene = mi.load_string(PATH_SCENE)
    integrator = scene.integrator()
    xy = grid_pattern(24, 24, 0.3).pixel_xy
    sizes = [n for n in range(20, len(xy)) if padded_size(n) == padded_size(len(xy) - 3)]
    assert len(sizes) >= 2 and padded_size(sizes[0]) > sizes[0]
    for n in sizes[:2]:
        padded = _trace(scene, integrator, xy[:n], True, pad=True)
        plain = _trace(scene, integrator, xy[:n], False)
        assert len(padded.radiance) == n
        for a, b in zip(_fields(padded), _fields(plain)):
            np.testing.assert_array_equal(a, b)
    before = recordings()
    _trace(scene, integrator, xy[:sizes[-1]], True, pad=True)  # another size, same bucket
    assert recordings() == before


def test_a_dropped_scene_is_let_go_and_a_held_one_kept():
    # a live scene's objects are Dr.Jit instances every later trace goes through
    import gc

    from mitsuba_mrt.renderer import replay

    def held():
        return [objects[0] for objects, _ in replay._held.values()]

    scene, kept = mi.load_string(PATH_SCENE), mi.load_string(PATH_SCENE)
    xy = grid_pattern(24, 24, 0.1).pixel_xy
    _trace(kept, kept.integrator(), xy, True)
    _trace(scene, scene.integrator(), xy, True)
    assert any(o is scene for o in held()) and any(o is kept for o in held())
    dropped = id(scene)
    del scene
    gc.collect()
    other = mi.load_string(PATH_SCENE)
    _trace(other, other.integrator(), xy, True)
    assert any(o is other for o in held())
    assert any(o is kept for o in held())  # its caller still holds it
    assert all(o is other for o in held() if id(o) == dropped)  # (other may reuse its id)


def test_a_token_stays_with_its_objects_and_is_never_given_again():
    # auto keys what renders measured by it: a later scene may get a freed one's ids
    import gc

    from mitsuba_mrt.renderer.replay import token

    scene = mi.load_string(PATH_SCENE)
    objects = (scene, scene.sensors()[0], scene.integrator())
    first = token(objects)
    assert token(objects) == first
    del scene, objects
    gc.collect()
    tokens = set()
    for _ in range(3):  # each new scene a new token, whatever ids it is given
        other = mi.load_string(PATH_SCENE)
        tokens.add(token((other, other.sensors()[0], other.integrator())))
        del other
        gc.collect()
    assert len(tokens) == 3 and first not in tokens


@pytest.mark.parametrize("mode", ["fast", "refine", "idpass", "paper"])
def test_another_spp_compiles_no_kernel(mode):
    # spp is a kernel input, not a literal: a second render at another spp
    # replays or reuses every kernel of the first (independent sampler: the
    # stratified and multijitter samplers' arithmetic bakes their count in)
    scene = mi.load_string(PATH_SCENE.replace(
        '<sampler type="stratified">', '<sampler type="independent">').replace(
        '<boolean name="jitter" value="false"/>', ''))
    mitsuba_mrt.render(scene, mode=mode, spp=3, sample_fraction=0.2)
    second = mitsuba_mrt.render(scene, mode=mode, spp=5, sample_fraction=0.2)
    assert (second.timings.compile.compiled, second.timings.compile.from_disk) == (0, 0)
    assert second.spp == 5


def test_a_trace_without_its_variance_has_the_same_values():
    # (the passes that estimate nothing ask for none: the kernels are the same)
    scene = mi.load_string(PATH_SCENE)
    xy = np.stack(np.meshgrid(np.arange(24), np.arange(24)), -1).reshape(-1, 2)
    kwargs = dict(box=True, ids=False)
    with_it = _trace(scene, scene.integrator(), xy, True, **kwargs)
    without = _trace(scene, scene.integrator(), xy, True, variance=False, **kwargs)
    assert without.variance is None and with_it.variance.any()
    for a, b in zip(_fields(with_it), _fields(without)):
        if b is not None:
            np.testing.assert_array_equal(a, b)


def test_a_full_render_denoised_records_the_passes_1_spp_launch():
    # auto plans that launch as replayed (no recording, no compilation) once it has run
    from mitsuba_mrt.renderer.api import GridTracer, render_denoised

    scene = mi.load_string(PATH_SCENE)
    sensor = scene.sensors()[0]
    tracer = GridTracer(scene, sensor, scene.integrator(), 4, 0)
    assert not tracer.pass_recorded(1)
    render_denoised(scene, spp=1)
    assert tracer.pass_recorded(1)
    assert not tracer.pass_recorded(2) and not tracer.pass_recorded(1, halves=True)
    with replaying(False):
        assert not tracer.pass_recorded(1)


def test_a_render_s_traces_replay_recordings_made_under_its_flags():
    # Dr.Jit records a frozen function again under other JIT flags (kernel
    # history on, as the passes' timed launches have it): a full render
    # denoised records under a render's flags, so a render's pass replays it
    import drjit as dr

    from mitsuba_mrt.renderer.api import GridTracer, render_denoised
    from mitsuba_mrt.runtime.jit import kernel_seconds, recording_flags

    scene = mi.load_string(PATH_SCENE)
    tracer = GridTracer(scene, scene.sensors()[0], scene.integrator(), 1, 0)
    xy = np.stack(np.meshgrid(np.arange(24), np.arange(24)), -1).reshape(-1, 2)
    render_denoised(scene, spp=1)
    before = recordings()
    with recording_flags(), kernel_seconds():
        tracer(xy, stream=7, aovs=True, ids=False, box=True, replay=True, variance=False)
    assert recordings() == before
    assert not dr.flag(dr.JitFlag.KernelHistory)  # (as it was)

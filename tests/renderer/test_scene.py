"""Loading scenes: film checks and warnings (renderer/scene.py)."""

import warnings

import mitsuba as mi
import numpy as np
import pytest

import mitsuba_mrt

from helpers import small_scene_xml
from mitsuba_mrt import MRTError, MRTWarning
from mitsuba_mrt.renderer import scene as scene_module
from mitsuba_mrt.recon.metrics import paper_error
from mitsuba_mrt.renderer.api import render_reference
from mitsuba_mrt.renderer.scene_query import replayable
from mitsuba_mrt.renderer.scene import (BYTES_PER_PIXEL, as_rgb, check_film, plugin_name,
                                      warn_negative_emitters, warn_nested_aovs)


def test_film_too_large_for_memory_is_refused_with_an_estimate(variant):
    scene = mi.load_string(small_scene_xml(res=100))
    check_film(scene, available=BYTES_PER_PIXEL * 100 * 100)
    with pytest.raises(MRTError, match=r"a 100 x 100 render needs about 2\.5 MB of memory "
                                       r"\(250 bytes per pixel\), more than the 2\.5 MB"):
        check_film(scene, available=BYTES_PER_PIXEL * 100 * 100 - 1)


def test_an_empty_film_is_refused(variant, tmp_path):
    path = tmp_path / "empty.xml"
    path.write_text(small_scene_xml(res=0))
    with pytest.raises(MRTError, match="the film is 0 x 0 pixels"):
        scene_module.load_scene(path)


def test_negative_emitters_are_named(variant):
    xml = """<scene version="3.0.0">
      <shape type="sphere" id="lamp"><emitter type="area"><rgb name="radiance" value="-1"/></emitter></shape>
      <emitter type="spot" id="spot"><rgb name="intensity" value="-2, 1, 1"/></emitter>
      <emitter type="point"><rgb name="intensity" value="3"/></emitter>
      <emitter type="directional"><rgb name="irradiance" value="-3"/></emitter>
    </scene>"""
    scene = mi.load_string(xml)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        messages = warn_negative_emitters(scene)
    assert [str(w.message) for w in caught] == messages
    assert all(w.category is MRTWarning for w in caught)
    assert len(messages) == 3
    assert any("of shape 'lamp' (AreaLight) has a negative radiance (-1)" in m for m in messages)
    assert any("emitter spot (SpotLight) has a negative intensity (-2)" in m for m in messages)
    assert any("(DirectionalEmitter) has a negative irradiance (-3)" in m for m in messages)


def test_a_nested_integrators_own_aovs_are_named_in_a_warning(variant):
    # the MRT's output is colour and its ids: the aov integrator's channels are not in it
    nested = ('<integrator type="aov"><string name="aovs" value="dd.y:depth,nn:sh_normal"/>'
              '<integrator type="path"/></integrator>')
    scene = mi.load_string(small_scene_xml(res=16, integrator=nested))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = mitsuba_mrt.render(scene, mode="fast")
    assert [str(w.message) for w in caught if w.category is MRTWarning] == [
        "the AOVIntegrator's 8 AOV channels (dd.y.T, nn.X, nn.Y, nn.Z, ...) are not in the "
        "MRT's output, only colour and the MRT's ids: mi.render with it gives them"]
    assert result.image.shape == (16, 16, 3)
    assert warn_nested_aovs(mi.load_dict({"type": "path"})) is None


def test_plugins_are_named_by_their_class(variant):
    assert plugin_name(mi.load_dict({"type": "hdrfilm"})) == "HDRFilm"  # (C++)
    assert plugin_name(mi.load_dict({"type": "matte"})) == "MatteIntegrator"  # (Python)


def test_unused_parameters_are_all_named():
    error = Exception("[parser.cpp:111] Found unused parameters:\n  - $foo=1\n  - $bar=2")
    assert scene_module._first_line(error) == \
        "[parser.cpp:111] Found unused parameters: $foo=1, $bar=2"
    assert scene_module._first_line(Exception("one line\nmore")) == "one line"


@pytest.mark.parametrize("sampler, expected", [
    ("independent", [1, 2, 3, 5, 8]), ("stratified", [1, 1, 1, 4, 4]),
    # none of these takes fewer than 4: its least, not 1, which it would not take
    ("orthogonal", [4, 4, 4, 4, 4]), ("ldsampler", [4, 4, 4, 4, 4])])
def test_a_launch_planned_for_some_spp_traces_no_more(variant, sampler, expected):
    from mitsuba_mrt.renderer.scene_query import sample_count_at_most

    taken = [sample_count_at_most(mi.load_dict({"type": sampler}), spp) for spp in (1, 2, 3, 5, 8)]
    assert taken == expected


def test_a_jit_variant_loads_the_scene_on_one_thread(variant, tmp_path, monkeypatch):
    # loaded on several threads, a scene's kernels came out in one of two
    # variable orders from process to process (CUDA), missing the disk cache
    path = tmp_path / "small.xml"
    path.write_text(small_scene_xml(res=8))
    calls = []
    load_file = mi.load_file
    monkeypatch.setattr(mi, "load_file", lambda *a, **k: calls.append(k) or load_file(*a, **k))
    scene_module.load_scene(path)
    assert calls[0]["parallel"] is variant.startswith("scalar")


def test_a_trace_of_no_samples_is_refused_not_launched(variant):
    # a kernel divides by the spp: a launch of 0 spp would end the process
    import numpy as np

    from mitsuba_mrt.renderer.trace import trace_pixels

    scene = mi.load_string(small_scene_xml())
    with pytest.raises(MRTError, match="spp must be >= 1, got 0"):
        trace_pixels(scene, scene.sensors()[0], scene.integrator(), np.zeros((1, 2), int), 0)


def test_a_parameter_that_sets_sample_count_below_one_is_refused(variant, tmp_path):
    # Mitsuba's stratified sampler rounds sample_count 0 up to 1 and renders
    path = tmp_path / "stratified.xml"
    path.write_text(small_scene_xml().replace('name="sample_count" value="1"', 'name="sample_count" value="$spp"')
                    .replace("<scene version=\"3.0.0\">",
                             "<scene version=\"3.0.0\"><default name=\"spp\" value=\"4\"/>"))
    assert scene_module.load_scene(path, spp=1).sensors()[0].sampler().sample_count() == 1
    for bad in (0, -2):
        with pytest.raises(MRTError, match=f"spp={bad} sets the scene's sample_count, "
                                           "which must be >= 1"):
            scene_module.load_scene(path, spp=bad)


def test_a_scene_whose_sampler_takes_no_samples_is_refused(variant):
    # mi.load_string takes sample_count 0; a render of it would end the process
    import mitsuba_mrt

    scene = mi.load_dict({"type": "scene", "shape": {"type": "sphere"},
                          "integrator": {"type": "path"},
                          "sensor": {"type": "perspective",
                                     "sampler": {"type": "independent", "sample_count": 0},
                                     "film": {"type": "hdrfilm", "width": 8, "height": 8}}})
    for call in (mitsuba_mrt.render, mitsuba_mrt.render_reference):
        with pytest.raises(MRTError, match="the scene's sampler takes sample_count >= 1, got 0"):
            call(scene)
    with pytest.raises(MRTError, match="spp must be >= 1, got 0"):
        mitsuba_mrt.render(scene, spp=0)


def test_an_integrator_that_is_none_or_not_one_is_refused(variant):
    import mitsuba_mrt

    bare = mi.load_dict({"type": "scene", "shape": {"type": "sphere"},
                         "sensor": {"type": "perspective",
                                    "film": {"type": "hdrfilm", "width": 8, "height": 8}}})
    with pytest.raises(MRTError, match=r"^the scene has no integrator: add one to it "
                                       r"\(in Python, or pass integrator=\)$"):
        mitsuba_mrt.render(bare)
    assert mitsuba_mrt.render(bare, integrator=mi.load_dict({"type": "path"})).image.shape[:2] \
        == (8, 8)
    scene = mi.load_string(small_scene_xml())
    with pytest.raises(MRTError, match="^integrator must be a Mitsuba integrator, got 3$"):
        mitsuba_mrt.render(scene, integrator=3)
    for bad in ("x", 1.0, True):
        with pytest.raises(MRTError, match="^sensor must be an index or a Mitsuba sensor"):
            mitsuba_mrt.render(scene, sensor=bad)
    with pytest.raises(MRTError, match=r"^spp must be an integer >= 1, got 2\.5$"):
        mitsuba_mrt.render(scene, spp=2.5)
    # a path or None raised AttributeError ('str' object has no attribute 'integrator')
    for bad in ("scene.xml", None):
        with pytest.raises(MRTError, match=r"^scene must be a Mitsuba scene \(mitsuba_mrt"
                                           r"\.load_scene loads a file\), got"):
            mitsuba_mrt.render(bad)
    with pytest.raises(MRTError, match=r"^progress must be callable as progress\(stage, done\)"):
        mitsuba_mrt.render(scene, progress=5)


def test_a_seed_a_sampler_cannot_take_is_refused(variant):
    import mitsuba_mrt

    scene = mi.load_string(small_scene_xml())
    calls = (mitsuba_mrt.render, mitsuba_mrt.render_reference, mitsuba_mrt.render_denoised)
    for call in calls:
        for bad in (-1, 1 << 32, 2.5, True):
            with pytest.raises(MRTError, match=r"^seed must be an integer in \[0, 2\^32\)"):
                call(scene, seed=bad)


def test_a_scene_s_description_key_is_its_content_s_not_its_shapes_order(variant):
    from mitsuba_mrt.renderer.scene_query import description_key

    def key(radii: tuple, pixels: int = 64) -> str:
        shapes = {f"ball{k}": {"type": "sphere", "radius": r, "center": [2.0 * k, 0, 0]}
                  for k, r in radii}
        scene = mi.load_dict({"type": "scene", "integrator": {"type": "path"},
                              "sensor": {"type": "perspective"}, **shapes})
        return description_key(scene, scene.sensors()[0], scene.integrator(), pixels)

    # (Mitsuba lists shapes in the order they loaded, which may differ between processes)
    assert key(((0, 1.0), (1, 0.5))) == key(((1, 0.5), (0, 1.0)))
    assert key(((0, 1.0), (1, 0.5))) != key(((0, 1.0), (1, 0.6)))
    assert key(((0, 1.0),), 64) != key(((0, 1.0),), 65)


def test_a_scene_s_description_key_is_the_same_after_a_full_render(variant):
    # (mi.render sets the sampler's wavefront size, which Mitsuba's description shows: a
    # process that rendered would not find what a fresh process remembered)
    from helpers import ball_scene_xml

    from mitsuba_mrt.renderer.api import render_reference
    from mitsuba_mrt.renderer.scene_query import description_key

    scene = mi.load_string(ball_scene_xml(32, spp=4))
    sensor = scene.sensors()[0]

    def key():
        return description_key(scene, sensor, scene.integrator(), 32 * 32)
    before, described = key(), str(sensor)
    render_reference(scene)
    assert key() == before
    if "scalar" not in variant:  # (a scalar render leaves the wavefront size as it was)
        assert str(sensor) != described


def _film_scene(pixel_format: str, integrator: str = '<integrator type="path"/>'):
    xml = small_scene_xml(16, integrator=integrator)
    return mi.load_string(xml.replace(
        '<rfilter type="box"/>',
        f'<rfilter type="box"/><string name="pixel_format" value="{pixel_format}"/>'))


@pytest.mark.parametrize("pixel_format", ["luminance", "luminance_alpha"])
def test_a_luminance_film_is_refused(variant, pixel_format):
    # its one channel was compared with the MRT's three ("image shape differs")
    with pytest.raises(MRTError, match=f"the film's pixel_format is {pixel_format}: "
                                       r"the MRT renders colour \(rgb, rgba, xyz, xyza\)"):
        mitsuba_mrt.render(_film_scene(pixel_format), mode="fast")


def test_an_xyz_film_renders_the_rgb_film_s_image(variant):
    # mi.render's XYZ was taken for RGB: a full render, and every error
    # against one, was in the wrong colours
    rgb, xyz = _film_scene("rgb"), _film_scene("xyz")
    reference = render_reference(rgb)[0]
    assert np.allclose(render_reference(xyz)[0], reference, atol=1e-5)
    assert (mitsuba_mrt.render(xyz, mode="fast").image
            == mitsuba_mrt.render(rgb, mode="fast").image).all()
    plugin = '<integrator type="mrt"><string name="mode" value="fast"/></integrator>'
    developed = np.array(mi.render(_film_scene("xyza", plugin)))  # the film's XYZ, alpha
    expected = np.array(mi.render(_film_scene("rgba", plugin)))
    film = _film_scene("xyza").sensors()[0].film()
    rgb, alpha = as_rgb(developed.astype(np.float64), film)
    assert np.allclose(rgb, expected[..., :3], atol=1e-5)
    assert (alpha == expected[..., 3]).all()


@pytest.mark.parametrize("sampler", ["orthogonal", "ldsampler"])
def test_the_id_pass_takes_the_sample_counts_a_sampler_takes(variant, sampler):
    # the albedo pass launched 16 samples a pixel, which orthogonal rounds up
    # to 25: "sample_count should be a multiple of samples_per_wavefront"
    xml = small_scene_xml(24, integrator='<integrator type="path"/>')
    start, end = xml.index('<sampler'), xml.index('</sampler>') + len('</sampler>')
    xml = (xml[:start] + f'<sampler type="{sampler}"><integer name="sample_count" value="49"/>'
           '</sampler>' + xml[end:])
    result = mitsuba_mrt.render(mi.load_string(xml), mode="idpass")
    assert np.isfinite(result.image).all() and result.image.max() > 0


def test_a_batch_sensor_renders_without_replays(variant):
    # its rays come from a host function: recording a replay of its trace
    # aborted the whole process (SIGABRT in Dr.Jit's RecordThreadState)
    cameras = "".join(f"""<sensor type="perspective"><float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="{o}" target="0, 0, 0" up="0, 1, 0"/>
        </transform></sensor>""" for o in ("0, 0, 8", "8, 0, 0"))
    xml = small_scene_xml(16, integrator='<integrator type="path"/>')
    start = xml.index('<sensor type="perspective">')
    xml = (xml[:start] + f'<sensor type="batch">{cameras}' +
           xml[xml.index('<sampler', start):].replace('value="16"/><integer name="height"',
                                                      'value="32"/><integer name="height"', 1))
    scene = mi.load_string(xml)
    assert not replayable(scene)
    reference = render_reference(scene, spp=16)[0]
    assert reference.shape == (16, 32, 3)
    for mode in ("fast", "idpass"):
        image = mitsuba_mrt.render(scene, spp=16, sample_fraction=1.0, mode=mode).image
        assert paper_error(image, reference) < 0.02

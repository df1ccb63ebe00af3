"""The Mitsuba side: matte shading, the sparse trace, the mrt plugin."""

import re

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import mitsuba_mrt
from mitsuba_mrt import MRTError, grid_pattern
from mitsuba_mrt.recon.metrics import paper_error
from mitsuba_mrt.renderer.api import render_reference
from helpers import small_scene_xml

LIGHTS = [((2.0, 2.0, 5.0), 60.0), ((-3.0, 0.0, 4.0), 40.0)]


def needs_ad(variant):
    """Skip where ``variant`` differentiates nothing (``scalar_rgb``, the
    fallback without libLLVM 17+): prb & co. exist only in AD variants."""
    if "_ad_" not in variant:
        pytest.skip(f"{variant} is not an AD variant")


def numpy_matte(o, d):
    """The report's shading for the small scene, evaluated in numpy."""
    def hit(o, d):
        # sphere r=1 at origin and the plane z = -1.5; returns (t, normal, albedo)
        b = np.dot(o, d)
        disc = b * b - (np.dot(o, o) - 1.0)
        best = (np.inf, None, None)
        if disc >= 0:
            for t in (-b - np.sqrt(disc), -b + np.sqrt(disc)):
                if t > 1e-4:
                    best = (t, o + t * d, np.array([0.8, 0.2, 0.2]))
                    break
        if abs(d[2]) > 1e-12:
            t = (-1.5 - o[2]) / d[2]
            if 1e-4 < t < best[0]:
                best = (t, np.array([0.0, 0.0, 1.0]), np.array([0.5, 0.5, 0.5]))
        t, n, albedo = best
        if n is not None and albedo[0] == 0.8:
            n = n / np.linalg.norm(n)
        return t, n, albedo

    t, n, albedo = hit(o, d)
    if n is None:
        return np.zeros(3)
    p = o + t * d
    energy = 0.0
    for pos, intensity in LIGHTS:
        to_light = np.array(pos) - p
        dist = np.linalg.norm(to_light)
        l = to_light / dist
        ts, _, _ = hit(p + 1e-4 * n, l)
        if ts < dist:
            continue
        energy += (intensity / np.pi) * max(0.0, float(np.dot(n, l))) / dist ** 2
    return albedo * energy


def test_matte_matches_the_report_formula(variant):
    res = 32
    scene = mi.load_string(small_scene_xml(res))
    image = np.array(mi.render(scene))[..., :3]
    sensor = scene.sensors()[0]
    pixels = [(16, 16), (20, 12), (5, 5), (28, 30), (10, 22), (14, 18), (25, 8)]
    for x, y in pixels:
        ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f((x + 0.5) / res, (y + 0.5) / res),
                                   mi.Point2f(0.5, 0.5))
        o = np.array(ray.o, dtype=np.float64).reshape(-1)
        d = np.array(ray.d, dtype=np.float64).reshape(-1)
        expected = numpy_matte(o, d / np.linalg.norm(d))
        assert np.allclose(image[y, x], expected, rtol=2e-4, atol=1e-6), (x, y)
    assert image.max() > 0.1  # the scene is lit


def test_matte_is_noise_free_at_one_spp(variant):
    scene = mi.load_string(small_scene_xml(16))
    a = np.array(mi.render(scene, seed=1))
    b = np.array(mi.render(scene, seed=2))
    assert np.array_equal(a, b)


def counting_integrator(nested):
    """A nested integrator that counts the lanes (rays) that reach it."""

    class CountingIntegrator(mi.SamplingIntegrator):
        def __init__(self):
            super().__init__(mi.Properties())
            self.rays = 0

        def sample(self, scene, sampler, ray, medium=None, active=True):
            self.rays += dr.width(ray.o.x) if dr.is_jit_v(mi.Float) else 1
            return nested.sample(scene, sampler, ray, medium, active)

    return CountingIntegrator()


@pytest.mark.parametrize("fraction,spp,taken", [(0.1, 1, 1), (0.25, 3, 4)])
def test_only_the_grid_pixels_are_traced(variant, fraction, spp, taken):
    scene = mi.load_string(small_scene_xml(40))
    counting = counting_integrator(scene.integrator())
    result = mitsuba_mrt.render(scene, counting, spp=spp, sample_fraction=fraction,
                                mode="paper")
    expected = grid_pattern(40, 40, fraction).count
    assert result.spp == taken  # the stratified sampler rounds 3 up to 4
    assert counting.rays == expected * taken
    assert result.traced_mask.sum() == expected


def test_traced_pixels_equal_the_full_render(variant):
    scene = mi.load_string(small_scene_xml(48))
    result = mitsuba_mrt.render(scene, sample_fraction=0.2, mode="fast")
    reference, _ = mitsuba_mrt.render_reference(scene)
    m = result.traced_mask
    assert np.allclose(result.image[m], reference[m], atol=1e-6)
    assert paper_error(result.image, reference) < 0.02


@pytest.mark.parametrize("kind", [{}, {"radiance": False}, {"box": True, "ids": False,
                                                               "halves": True}])
def test_a_trace_of_no_pixels_is_empty(variant, kind):
    # a launch over no lanes aborts Dr.Jit's whole process, past any ``except``
    from mitsuba_mrt.renderer.trace import trace_pixels

    scene = mi.load_string(small_scene_xml(8))
    none = trace_pixels(scene, scene.sensors()[0], scene.integrator(),
                        np.zeros((0, 2), np.int64), 4, replay=True, **kind)
    one = trace_pixels(scene, scene.sensors()[0], scene.integrator(),
                       np.zeros((1, 2), np.int64), 4, **kind)
    for field in ("radiance", "albedo", "shape_index", "normal", "variance", "odd", "alpha"):
        full, empty = getattr(one, field), getattr(none, field)
        assert (empty is None) == (full is None)
        assert empty is None or empty.shape == (0, *full.shape[1:])


def test_ids_come_from_the_trace(variant):
    scene = mi.load_string(small_scene_xml(32))
    result = mitsuba_mrt.render(scene, sample_fraction=0.3, id_rule="exact", mode="paper")
    trace = result.trace
    assert set(np.unique(trace.shape_index)) == {1, 2}  # sphere, floor (no background)
    assert trace.num_lights == 2
    centre = np.flatnonzero((result.pattern.pixel_xy == [15, 15]).all(axis=1))
    if len(centre):  # the sphere's front sees light 0 and light 1
        assert trace.shape_index[centre[0]] == 1 and trace.visible_lights[centre[0]] == 0b11
    assert np.allclose(trace.albedo[trace.shape_index == 1], [0.8, 0.2, 0.2])


def test_mrt_plugin_from_xml(variant):
    xml = small_scene_xml(32, integrator="""<integrator type="mrt">
        <float name="sample_fraction" value="0.25"/><float name="filter_sigma" value="1.5"/>
        <string name="mode" value="paper"/>
        <integrator type="matte"/></integrator>""")
    scene = mi.load_string(xml)
    integrator = scene.integrator()
    assert integrator.params.sample_fraction == 0.25 and integrator.params.filter_sigma == 1.5
    assert integrator.aov_names() == ["id", "shape_index", "visible_lights", "traced"]
    image = np.array(mi.render(scene))
    assert image.shape == (32, 32, 7)
    assert image[..., 6].sum() == grid_pattern(32, 32, 0.25).count
    assert set(np.unique(image[..., 4])) <= {0.0, 1.0, 2.0}
    full = np.array(mi.render(scene, integrator=integrator.nested))
    traced = image[..., 6] == 1
    assert np.allclose(image[traced][:, :3], full[traced][:, :3], atol=1e-6)
    # the API sees the wrapper's parameters
    assert mitsuba_mrt.render(scene, mode="paper").params.filter_sigma == 1.5


@pytest.mark.parametrize("use_scalar", [False, True])
def test_mrt_plugin_fills_the_film(variant, use_scalar):
    # mi.render's result, film.bitmap() and film.write() all see the MRT image
    xml = small_scene_xml(24, integrator="""<integrator type="mrt">
        <string name="mode" value="fast"/><integrator type="matte"/></integrator>""")
    try:
        if use_scalar:
            mi.set_variant("scalar_rgb")
        scene = mi.load_string(xml)
        image = np.array(mi.render(scene))
        bitmap = np.array(scene.sensors()[0].film().bitmap())
        reconstructed = scene.integrator().last_result.image
    finally:
        mi.set_variant(variant)
    assert image.shape == bitmap.shape == (24, 24, 7)
    assert np.allclose(image, bitmap, atol=1e-6)
    assert np.allclose(image[..., :3], reconstructed, atol=1e-6)


def test_mrt_plugin_rejects_bad_parameters(variant):
    for kind, name, value, message in [
            ("float", "sample_fraction", "0", "sample_fraction"),
            ("float", "filter_sigma", "-1", "filter_sigma"),
            # (int() truncated these to 2 and 0; the text raised a ValueError, the bool became 1.0)
            ("float", "max_inpoints", "2.5", "max_inpoints must be an integer >= 1, got 2.5"),
            ("float", "num_cappoints", "-0.5", "num_cappoints must be an integer >= 0, got -0.5"),
            ("string", "max_inpoints", "abc", "max_inpoints must be a number, got 'abc'"),
            ("boolean", "sample_fraction", "true", "sample_fraction must be a number, got True")]:
        xml = small_scene_xml(8, integrator=f'<integrator type="mrt"><{kind} name="{name}" '
                                            f'value="{value}"/></integrator>')
        with pytest.raises(Exception, match=re.escape(message)):
            mi.load_string(xml)


def test_mrt_plugin_reads_numbers_of_any_xml_type(variant):
    xml = small_scene_xml(8, integrator="""<integrator type="mrt">
        <string name="sample_fraction" value="0.25"/><float name="max_inpoints" value="50"/>
        <integer name="filter_sigma" value="2"/></integrator>""")
    params = mi.load_string(xml).integrator().params
    assert (params.sample_fraction, params.max_inpoints, params.filter_sigma) == (0.25, 50, 2.0)
    assert type(params.max_inpoints) is int and type(params.filter_sigma) is float


def test_mrt_plugin_with_path_integrator(variant):
    xml = small_scene_xml(24, integrator="""<integrator type="mrt">
        <integrator type="path"><integer name="max_depth" value="3"/></integrator></integrator>""")
    image = np.array(mi.render(mi.load_string(xml), spp=4))
    assert np.isfinite(image).all() and image[..., :3].max() > 0


@pytest.mark.parametrize("nested", ["prb", "prbvolpath", "direct_projective"])
def test_differentiable_python_integrators_trace_their_primal_image(variant, nested):
    # Their sample() takes an AD mode and derivative state, not (scene, sampler,
    # ray, medium, active): every mode raised a TypeError (exit status 1)
    needs_ad(variant)
    xml = small_scene_xml(16, integrator=f'<integrator type="{nested}"/>')
    scene = mi.load_string(xml)
    reference = np.array(mi.render(scene, spp=64))[..., :3]
    assert reference.max() > 0
    for mode in ("fast", "refine"):
        result = mitsuba_mrt.render(scene, spp=64, sample_fraction=1.0, mode=mode)
        assert result.traced_mask.all()
        assert paper_error(result.image, reference) < 0.01
    plugin = mi.load_string(small_scene_xml(16, integrator=f"""<integrator type="mrt">
        <integrator type="{nested}"/><string name="mode" value="fast"/></integrator>"""))
    direct = mitsuba_mrt.render(scene, spp=64, mode="fast").image
    assert np.allclose(np.array(mi.render(plugin, spp=64))[..., :3], direct, atol=1e-6)


@pytest.mark.parametrize("nested", ["path", "prb"])
def test_the_plugin_answers_a_per_ray_query_with_its_nested_integrators_sample(variant, nested):
    # (another integrator asking the mrt plugin for one ray's radiance)
    if nested == "prb":
        needs_ad(variant)
    scene = mi.load_string(small_scene_xml(16))
    ray, _ = scene.sensors()[0].sample_ray(0.0, 0.5, mi.Point2f(0.5, 0.5), mi.Point2f(0.5, 0.5))

    def one(integrator, query):
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(7, 1)
        value, valid, aovs = query(integrator, sampler)
        return np.array(value, dtype=np.float64).ravel(), bool(np.all(valid)), aovs

    plugin = mi.load_dict({"type": "mrt", "nested": {"type": nested}})
    value, valid, aovs = one(plugin, lambda it, s: it.sample(scene, s, ray, None, True))
    assert valid and aovs == [] and np.isfinite(value).all() and value.max() > 0
    if nested == "path":  # (prb's sample takes an AD mode: not callable so)
        alone = mi.load_dict({"type": nested})
        assert np.array_equal(value, one(alone, lambda it, s: it.sample(scene, s, ray, None,
                                                                          True))[0])


def test_mrt_plugin_renders_scenes_with_parameters_to_differentiate(variant):
    # mi.render passes the seed as a Dr.Jit array there: int() of it raised a
    # TypeError; the reconstruction has no derivatives, which dr.backward says
    needs_ad(variant)
    scene = mi.load_string(small_scene_xml(16, integrator="""<integrator type="mrt">
        <integrator type="path"/><string name="mode" value="fast"/></integrator>"""))
    params = mi.traverse(scene)
    dr.enable_grad(params["ball.bsdf.reflectance.value"])
    params.update()
    image = mi.render(scene, params, spp=4, seed=3)
    plain = mitsuba_mrt.render(scene, spp=4, seed=3, mode="fast").image
    assert np.allclose(np.array(image)[..., :3], plain, atol=1e-6)
    with pytest.raises(MRTError, match="mrt: its reconstruction is not differentiable"):
        dr.backward(dr.mean(image))
    # matte, a plain sampling integrator, keeps Mitsuba's own derivatives
    matte = mi.load_string(small_scene_xml(16))
    params = mi.traverse(matte)
    dr.enable_grad(params["ball.bsdf.reflectance.value"])
    params.update()
    dr.backward(dr.mean(mi.render(matte, params, spp=1)))
    assert (np.array(dr.grad(params["ball.bsdf.reflectance.value"])) > 0).all()


@pytest.mark.parametrize("kind", ["no_shapes", "no_lights"])
def test_degenerate_scenes_render_without_nan(variant, kind):
    scene = mi.load_string(small_scene_xml(24, shapes=kind != "no_shapes",
                                           lights=kind != "no_lights"))
    for mode in ("paper", "fast", "auto"):
        result = mitsuba_mrt.render(scene, mode=mode)
        assert np.isfinite(result.image).all()
        assert (result.image == 0).all()


def test_nan_radiance_is_a_clear_error(variant):
    class NaNIntegrator(mi.SamplingIntegrator):
        def sample(self, scene, sampler, ray, medium=None, active=True):
            return mi.Color3f(dr.nan), mi.Bool(True), []

    scene = mi.load_string(small_scene_xml(16))
    with pytest.raises(MRTError, match="NaN or Inf radiance at 256 of 256"):
        mitsuba_mrt.render(scene, NaNIntegrator(mi.Properties()), sample_fraction=1.0,
                           mode="paper")


@pytest.mark.parametrize("mode", ["paper", "fast", "refine", "idpass"])
def test_scalar_variant_gives_the_same_trace(variant, mode):
    xml = small_scene_xml(24)
    llvm_result = mitsuba_mrt.render(mi.load_string(xml), sample_fraction=0.2, mode=mode)
    try:
        mi.set_variant("scalar_rgb")
        scalar_result = mitsuba_mrt.render(mi.load_string(xml), sample_fraction=0.2,
                                           mode=mode)
    finally:
        mi.set_variant(variant)
    assert np.allclose(scalar_result.trace.radiance, llvm_result.trace.radiance, atol=1e-5)
    assert np.array_equal(scalar_result.trace.shape_index, llvm_result.trace.shape_index)
    assert np.array_equal(scalar_result.trace.visible_lights, llvm_result.trace.visible_lights)
    assert np.allclose(scalar_result.image, llvm_result.image, atol=1e-4)


@pytest.mark.parametrize("kind", ["mono", "spectral_polarized"])
def test_monochromatic_and_polarized_variants_render(variant, kind):
    # mono: Color3f of a one-channel spectrum raised a TypeError, and its film's
    # luminance was refused; polarized: dr.max of a Mueller matrix had no bindings
    name = f"{variant.split('_')[0]}_ad_{kind}"
    if name not in mi.variants():
        pytest.skip(f"Mitsuba has no {name} variant")
    xml = small_scene_xml(24, integrator='<integrator type="path"/>')
    try:
        mi.set_variant(name)
        scene = mi.load_string(xml)
        reference = render_reference(scene, spp=64)[0]
        images = {mode: mitsuba_mrt.render(scene, spp=64, sample_fraction=1.0, mode=mode).image
                  for mode in ("fast", "idpass")}
    finally:
        mi.set_variant(variant)
    assert reference.shape == (24, 24, 3) and reference.max() > 0
    for image in images.values():
        assert paper_error(image, reference) < 0.01
        if kind == "mono":  # grey, as Mitsuba develops a monochromatic sample
            assert (image == image[..., :1]).all()


def test_a_plugin_that_denoised_leaves_no_oidn_object_for_nanobind_to_report(tmp_path):
    # the OIDN device and filters are let go before Python unloads the extension
    import subprocess
    import sys

    pytest.importorskip("mitsuba_oidn")
    scene = tmp_path / "scene.xml"
    scene.write_text(small_scene_xml(16, '<integrator type="mrt"><string name="mode" '
                                         'value="idpass"/><string name="denoise" value="oidn"/>'
                                         '<integrator type="path"/></integrator>'))
    child = ("import sys, mitsuba as mi, mitsuba_mrt\n"
             "mitsuba_mrt.activate(sys.argv[2])\n"
             "scene = mi.load_file(sys.argv[1])\n"
             "mi.render(scene)\n")
    proc = subprocess.run([sys.executable, "-c", child, str(scene), mi.variant()],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "leaked" not in proc.stderr


@pytest.mark.parametrize("props, message", [
    ('<string name="mode" value="magic"/>', "unknown mode 'magic'"),
    ('<string name="mode" value="refine"/><float name="time_limit" value="1"/>',
     "time_limit applies to mode auto only, not to mode 'refine'"),
    ('<string name="mode" value="fast"/><float name="noise_threshold" value="0.1"/>',
     "noise_threshold applies to mode auto only, not to mode 'fast'")])
def test_the_plugins_bad_mode_and_controls_are_refused_when_it_loads(variant, props, message):
    with pytest.raises(Exception, match=message):
        mi.load_string(small_scene_xml(16, f'<integrator type="mrt">{props}</integrator>'))

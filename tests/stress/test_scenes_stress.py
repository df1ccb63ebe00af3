"""Stress scenes for the Mitsuba side: tiny and huge scales, a grazing camera,
a camera inside a sphere or in fog, thousands of tiny shapes, a
cut-out, a sun beside point lights, degenerate BSDF parameters.  Each mode must give a finite image, non-negative wherever the
traced radiance is (Mitsuba itself returns negative radiance for some
invalid BSDFs), or raise a clear MRTError.  Renders are 16 x 16; the
thorough profile (MITSUBA_MRT_STRESS=thorough) adds the BSDFs under ``matte``.
"""

from __future__ import annotations

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba")

import mitsuba_mrt  # noqa: E402
from mitsuba_mrt import MRTError  # noqa: E402

from .stress_support import MODES, SOFT as THOROUGH  # noqa: E402

RES = 16
MATTE = '<integrator type="matte"/>'
PATH = '<integrator type="path"><integer name="max_depth" value="3"/></integrator>'


def scene_xml(s: float = 1.0, origin=(0, 0, 8), target=(0, 0, 0), up=(0, 1, 0),
              sphere_bsdf: str = '<bsdf type="diffuse"><rgb name="reflectance" value="0.8, 0.2, 0.2"/></bsdf>',
              integrator: str = MATTE, spp: int = 1, extra: str = "", fov: float = 40) -> str:
    """The sphere-on-a-plane scene of tests/helpers.py, every length times ``s``
    (light intensities times s^2, so that the image does not change)."""
    ox, oy, oz = (v * s for v in origin)
    tx, ty, tz = (v * s for v in target)
    return f"""<scene version="3.0.0">
  {integrator}
  <sensor type="perspective">
    <float name="fov" value="{fov}"/><float name="near_clip" value="{1e-2 * s}"/>
    <float name="far_clip" value="{1e4 * s}"/>
    <transform name="to_world"><lookat origin="{ox}, {oy}, {oz}" target="{tx}, {ty}, {tz}"
      up="{up[0]}, {up[1]}, {up[2]}"/></transform>
    <sampler type="independent"><integer name="sample_count" value="{spp}"/></sampler>
    <film type="hdrfilm"><integer name="width" value="{RES}"/><integer name="height" value="{RES}"/>
      <rfilter type="box"/></film>
  </sensor>
  <shape type="sphere"><point name="center" x="0" y="0" z="0"/><float name="radius" value="{s}"/>
    {sphere_bsdf}</shape>
  <shape type="rectangle">
    <transform name="to_world"><scale value="{20 * s}"/><translate z="{-1.5 * s}"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf>
  </shape>
  <emitter type="point"><point name="position" x="{2 * s}" y="{2 * s}" z="{5 * s}"/>
    <rgb name="intensity" value="{60 * s * s}"/></emitter>
  <emitter type="point"><point name="position" x="{-3 * s}" y="0" z="{4 * s}"/>
    <rgb name="intensity" value="{40 * s * s}"/></emitter>
  {extra}
</scene>"""


def _many_spheres(count: int = 1000) -> str:
    xy = np.random.default_rng(0).uniform(-3, 3, (count, 2))
    return "".join(f'<shape type="sphere"><point name="center" x="{x:.4f}" y="{y:.4f}" z="1.2"/>'
                   f'<float name="radius" value="0.015"/></shape>' for x, y in xy)


def _triangle_soup(path, count: int = 3000) -> str:
    """One mesh of ``count`` tiny disconnected triangles (an OBJ file)."""
    rng = np.random.default_rng(1)
    centres = np.column_stack([rng.uniform(-3, 3, (count, 2)), np.full(count, 1.2)])
    corners = centres[:, None, :] + rng.normal(0, 0.01, (count, 3, 3))
    lines = [f"v {x:.5f} {y:.5f} {z:.5f}" for x, y, z in corners.reshape(-1, 3)]
    lines += [f"f {3 * k + 1} {3 * k + 2} {3 * k + 3}" for k in range(count)]
    path.write_text("\n".join(lines) + "\n")
    return f'<shape type="obj"><string name="filename" value="{path}"/></shape>'


#: A cut-out (opaque and half-transparent squares, holes) before the sphere.
_CUTOUT = """<shape type="rectangle"><transform name="to_world"><translate z="3"/></transform>
  <bsdf type="mask"><texture type="checkerboard" name="opacity">
    <rgb name="color0" value="0"/><rgb name="color1" value="0.6"/>
    <transform name="to_uv"><scale x="5" y="5"/></transform></texture><bsdf type="diffuse"/></bsdf>
</shape>"""
#: Fog around the camera (a surface 8 away keeps a tenth of its light), and a sun.
_FOG = ('<integrator type="volpath"><integer name="max_depth" value="4"/></integrator>'
        '<medium type="homogeneous" id="fog"><rgb name="albedo" value="0.9"/>'
        '<float name="sigma_t" value="0.3"/></medium>')
_SUN = ('<emitter type="directional"><vector name="direction" x="0.3" y="0.2" z="-1"/>'
        '<rgb name="irradiance" value="2"/></emitter>')


def _in_fog(xml: str) -> str:
    return xml.replace('<sensor type="perspective">',
                       '<sensor type="perspective"><ref id="fog" name="exterior"/>', 1)


SCENES = {
    "scale_1e-4": lambda tmp: scene_xml(1e-4),
    "scale_1e4": lambda tmp: scene_xml(1e4),
    "grazing_camera": lambda tmp: scene_xml(origin=(0, -12, -1.499), target=(0, 10, -1.5),
                                            up=(0, 0, 1)),
    "camera_inside_sphere": lambda tmp: scene_xml(
        origin=(0, 0, 0.2), target=(0, 0, -1),
        extra='<emitter type="point"><point name="position" x="0.1" y="0.2" z="0"/>'
              '<rgb name="intensity" value="1"/></emitter>'),
    "many_tiny_spheres": lambda tmp: scene_xml(extra=_many_spheres()),
    "triangle_soup": lambda tmp: scene_xml(extra=_triangle_soup(tmp / "soup.obj")),
    "cutout_before_sphere": lambda tmp: scene_xml(integrator=PATH, spp=4, extra=_CUTOUT),
    "camera_in_fog": lambda tmp: _in_fog(scene_xml(integrator=_FOG, spp=4)),
    "sun_and_points": lambda tmp: scene_xml(integrator=PATH, spp=4, extra=_SUN),
}

#: BSDF parameters at or past the edge of their range; Mitsuba accepts these.
BSDFS = {
    "diffuse_control": '<bsdf type="diffuse"/>',  # nothing degenerate: the reference
    "roughconductor_alpha_0": '<bsdf type="roughconductor"><float name="alpha" value="0"/></bsdf>',
    "roughconductor_alpha_negative": '<bsdf type="roughconductor"><float name="alpha" value="-0.5"/></bsdf>',
    "roughconductor_alpha_nan": '<bsdf type="roughconductor"><float name="alpha" value="nan"/></bsdf>',
    "roughconductor_eta_k_0": ('<bsdf type="roughconductor"><float name="alpha" value="0.1"/>'
                               '<spectrum name="eta" value="0"/><spectrum name="k" value="0"/></bsdf>'),
    "roughplastic_alpha_0": '<bsdf type="roughplastic"><float name="alpha" value="0"/></bsdf>',
    "principled_roughness_negative": '<bsdf type="principled"><float name="roughness" value="-1"/></bsdf>',
}


def _check(result, what: str):
    image = result.image
    assert image.shape == (RES, RES, 3), what
    bad = ~np.isfinite(image)
    assert not bad.any(), f"{what}: {int(bad.any(-1).sum())} non-finite pixels"
    # every traced pixel (grid, and refine's or idpass's extra ones) holds its
    # traced radiance: where Mitsuba's radiance is non-negative, so is the image
    traced = image[result.traced_mask]
    if (traced >= 0).all():
        assert image.min() >= 0, (
            f"{what}: {int((image < 0).any(-1).sum())} negative pixels, down to {image.min():.4g} "
            f"(traced radiance in [0, {traced.max():.4g}])")


def _render(xml: str, mode: str, what: str):
    scene = mi.load_string(xml)
    try:
        result = mitsuba_mrt.render(scene, mode=mode, sample_fraction=0.25)
    except MRTError:
        return  # a clear refusal is an acceptable answer
    _check(result, what)


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("name", list(SCENES))
def test_stress_scene(name, mode, tmp_path, variant):
    _render(SCENES[name](tmp_path), mode, f"{name}/{mode}")


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("integrator", ["path", "matte"] if THOROUGH else ["path"])
@pytest.mark.parametrize("bsdf", list(BSDFS))
def test_degenerate_bsdf(bsdf, integrator, mode, variant):
    xml = scene_xml(sphere_bsdf=BSDFS[bsdf], integrator=MATTE if integrator == "matte" else PATH,
                    spp=1 if integrator == "matte" else 4)
    _render(xml, mode, f"{bsdf}/{integrator}/{mode}")

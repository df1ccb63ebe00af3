"""Plain helpers of the tests, imported as a module (``from helpers import SCENES``):
each has a use at module level (a parametrize list, a module's constant) where a
fixture does not fit.  pyproject.toml puts this folder on ``sys.path``
(``pythonpath = ["tests"]``); fixtures are in conftest.py.
"""

from __future__ import annotations

from pathlib import Path

#: The repository's root, and its scenes.
ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "scenes_xml"


def small_scene_xml(res: int = 32, integrator: str = '<integrator type="matte"/>',
                    extra: str = "", lights: bool = True, shapes: bool = True) -> str:
    """A red sphere on a grey plane, two point lights, a box-filtered film."""
    body = ""
    if shapes:
        body += """
  <shape type="sphere" id="ball">
    <point name="center" x="0" y="0" z="0"/><float name="radius" value="1"/>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.8, 0.2, 0.2"/></bsdf>
  </shape>
  <shape type="rectangle" id="floor">
    <transform name="to_world"><scale value="20"/><translate z="-1.5"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf>
  </shape>"""
    if lights:
        body += """
  <emitter type="point"><point name="position" x="2" y="2" z="5"/><rgb name="intensity" value="60"/></emitter>
  <emitter type="point"><point name="position" x="-3" y="0" z="4"/><rgb name="intensity" value="40"/></emitter>"""
    return f"""<scene version="3.0.0">
  {integrator}
  <sensor type="perspective">
    <float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0, 0, 8" target="0, 0, 0" up="0, 1, 0"/></transform>
    <sampler type="stratified"><integer name="sample_count" value="1"/><boolean name="jitter" value="false"/></sampler>
    <film type="hdrfilm"><integer name="width" value="{res}"/><integer name="height" value="{res}"/>
      <rfilter type="box"/></film>
  </sensor>{body}
  {extra}
</scene>"""


def path_camera_xml(res: int, spp: int = 8, rfilter: str = "box",
                    sampler: str = "independent", max_depth: int = 4) -> str:
    """A scene's opening: ``path`` and a camera 8 units in front of the origin."""
    return f"""<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="{max_depth}"/></integrator>
  <sensor type="perspective">
    <float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0, 0, 8" target="0, 0, 0" up="0, 1, 0"/></transform>
    <sampler type="{sampler}"><integer name="sample_count" value="{spp}"/></sampler>
    <film type="hdrfilm"><integer name="width" value="{res}"/><integer name="height" value="{res}"/>
      <rfilter type="{rfilter}"/></film>
  </sensor>"""


def ball_scene_xml(res: int, spp: int = 8, rfilter: str = "box",
                   sampler: str = "independent", max_depth: int = 4) -> str:
    """A diffuse ball on a plane under an area light, path traced: noisy, as real scenes are."""
    return path_camera_xml(res, spp, rfilter, sampler, max_depth) + """
  <shape type="sphere"><float name="radius" value="1"/>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.8, 0.2, 0.2"/></bsdf></shape>
  <shape type="rectangle">
    <transform name="to_world"><scale value="20"/><translate z="-1.5"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf></shape>
  <shape type="sphere"><point name="center" x="2" y="3" z="4"/><float name="radius" value="0.5"/>
    <emitter type="area"><rgb name="radiance" value="8"/></emitter></shape>
</scene>"""

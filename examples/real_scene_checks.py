"""The MRT's modes on kinds of scene the bundled ones lack: a cut-out, fog, a sun.

    python examples/real_scene_checks.py [--res 256] [--seeds 3] [--truth-spp 1024]

Each scene is written here (a sphere, a box or a second sphere, a floor;
``path`` or ``volpath`` at 64 spp):

- ``cutout``: a leaf-like cut-out (a ``mask`` BSDF, checkerboard opacity 0
  or 1) before the spheres; ``cutout_half``: the same at opacity 0.2 and 0.4.
- ``fog``: the camera inside a homogeneous medium (the sensor's ``exterior``).
- ``sun``: a ``directional`` light; ``sun_sky``: and a constant sky.

Printed per scene: the error (the report's metric) of the full render and
of each MRT mode against a converged render (``--truth-spp``), the mean over
``--seeds`` seeds, and the default ``auto``'s (its first seed's; a denoised
image is box-filtered, the converged render through the film's filter) with
what it chose.
"""

import argparse
import os

import numpy as np

#: The scenes' shared parts: the camera (``{medium}``: a reference or nothing) and the floor.
BASE = """<scene version="3.0.0">
  {integrator}
  <sensor type="perspective">{medium}
    <transform name="to_world"><lookat origin="0, 2, 6" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="{res}"/><integer name="height" value="{res}"/></film>
    <sampler type="independent"><integer name="sample_count" value="64"/></sampler>
  </sensor>
  <shape type="sphere"><transform name="to_world"><translate x="0.9"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.3, 0.2"/></bsdf></shape>
  <shape type="cube"><transform name="to_world"><scale value="0.5"/><translate x="-1.3" y="-0.5"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.4, 0.7"/></bsdf></shape>
  <shape type="rectangle"><transform name="to_world"><rotate x="1" angle="-90"/><scale value="6"/>
    <translate y="-1"/></transform><bsdf type="diffuse"/></shape>
  {extra}
</scene>"""
POINT = ('<emitter type="point"><point name="position" x="2" y="4" z="3"/>'
         '<rgb name="intensity" value="40"/></emitter>')
SKY = '<emitter type="constant"><rgb name="radiance" value="0.2"/></emitter>'
SUN = ('<emitter type="directional"><vector name="direction" x="-1" y="-1.2" z="-0.6"/>'
       '<rgb name="irradiance" value="3"/></emitter>')


def cutout(opacities: tuple) -> str:
    """A 2.4-wide square before the objects, its opacity a checkerboard of ``opacities``."""
    low, high = opacities
    return f"""<shape type="rectangle"><transform name="to_world"><scale value="1.2"/>
      <translate y="0.2" z="2"/></transform>
      <bsdf type="mask"><texture type="checkerboard" name="opacity">
        <rgb name="color0" value="{low}"/><rgb name="color1" value="{high}"/>
        <transform name="to_uv"><scale x="6" y="6"/></transform></texture>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.6, 0.2"/></bsdf></bsdf>
    </shape>"""


PATH = '<integrator type="path"/>'
FOG = ('<integrator type="volpath"/><medium type="homogeneous" id="fog">'
       '<rgb name="albedo" value="0.9"/><float name="sigma_t" value="0.08"/></medium>')
SCENES = {
    "cutout": dict(integrator=PATH, medium="", extra=POINT + SKY + cutout((0, 1))),
    "cutout_half": dict(integrator=PATH, medium="", extra=POINT + SKY + cutout((0.4, 0.2))),
    "fog": dict(integrator=FOG, medium='<ref id="fog" name="exterior"/>', extra=POINT + SKY),
    "sun": dict(integrator=PATH, medium="", extra=SUN),
    "sun_sky": dict(integrator=PATH, medium="", extra=SUN + SKY),
}
MODES = ("fast", "refine", "idpass")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--res", type=int, default=256)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--truth-spp", type=int, default=1024)
    args = parser.parse_args()
    # (a measurement plans from what its own process measures)
    os.environ.setdefault("MITSUBA_MRT_MEMORY", "off")
    import mitsuba as mi

    import mitsuba_mrt
    from mitsuba_mrt.recon.metrics import paper_error

    variant = mitsuba_mrt.activate("auto")
    print(f"[{variant}] error against {args.truth_spp} spp, mean of {args.seeds} seeds")
    print(f"{'scene':12s} {'full':>8s} " + " ".join(f"{m:>8s}" for m in MODES)
          + f" {'auto':>8s}  auto chose")
    for name, parts in SCENES.items():
        scene = mi.load_string(BASE.format(res=args.res, **parts))
        truth = mitsuba_mrt.render_reference(scene, spp=args.truth_spp, seed=1000)[0]
        seeds = range(args.seeds)
        row = [np.mean([paper_error(mitsuba_mrt.render_reference(scene, seed=s)[0], truth)
                        for s in seeds])]
        row += [np.mean([paper_error(mitsuba_mrt.render(scene, mode=m, seed=s).image, truth)
                         for s in seeds]) for m in MODES]
        auto = mitsuba_mrt.render(scene)
        row.append(paper_error(auto.image, truth))
        print(f"{name:12s} " + " ".join(f"{e:8.5f}" for e in row) + f"  {auto.auto.choice.label}")


if __name__ == "__main__":
    main()

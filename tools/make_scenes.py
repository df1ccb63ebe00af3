#!/usr/bin/env python3
"""Generate the Mitsuba 3 scene files of the MRT report into ``scenes_xml/``.

The scenes are those of ``/work/shared/paper/paper_scenes.md`` (the numbers
behind the report's figures).  Every file follows the same conventions:

* ``$res``, ``$spp``, ``$integrator`` and ``$jitter`` are ``<default>``
  parameters that a caller may override (``mi.load_file(path, res=64)``).
* The sensor is the report's pinhole eye: a ``perspective`` camera at
  distance 25 from a 20 x 20 window centred on the origin, so
  ``fov = 2 atan(10 / 25)`` along x.  With the ``stratified`` sampler,
  ``jitter=false`` and ``spp=1`` the single ray of a pixel passes through
  its exact centre, like the report's ray-tracer.  Image column ``c`` and
  row ``r`` (row 0 at the top) are the report's pixel ``(i, j) =
  (c, res - 1 - r)``; for the eye at ``z = -25`` a mirror ``<scale x="-1"/>``
  keeps world +x on the right of the image, as in the report.
* Spheres are ``sphere`` shapes and the report's infinite one-sided planes
  are large ``rectangle`` shapes whose normal is the plane's normal; all
  have a ``diffuse`` BSDF whose reflectance is the object colour (the back
  of a diffuse rectangle is black, i.e. one-sided).
* A light of strength ``k`` is a ``point`` emitter of intensity ``pi * k``
  (the diffuse BSDF's ``1 / pi`` is absent from the report's formula).
* Shapes carry ids ``obj_<n>_sphere`` / ``obj_<n>_plane`` numbered in table order
  (so that mitsuba_mrt, which numbers shapes by natural sort of their ids,
  numbers them as the report does),
  spheres first.

The output is deterministic: running the script twice gives the same bytes.

Usage::

    python tools/make_scenes.py [--out scenes_xml]
"""

import argparse
import math
from pathlib import Path

import numpy as np

#: Distance from the eye to the window plane z = 0.
EYE_DISTANCE = 25.0
#: Side of the square window (W * s in the report), in world units.
WINDOW_SIZE = 20.0
#: Half side of the square rectangles that stand in for the report's infinite
#: planes.  Mitsuba's rectangle hit points carry an error of about
#: 2.4e-7 * half side (world units), so the rectangles are no larger than
#: needed.  In Fig. 1 and the objects and lights tests every plane point that
#: is seen or crossed by a shadow ray lies within 60 units of the plane's
#: point, at any resolution.
PLANE_HALF_SIZE = 100.0
#: In the fraction scene the planes run to the horizon: at 200 x 200 the
#: central rows hit them up to 1750 units away (t = 3.5 / (10 / res) for
#: the upper plane); 2000 covers every pixel up to res 231 (beyond that the
#: farthest rows show background; checked against the report model).
FRACTION_PLANE_HALF_SIZE = 2000.0
#: Camera clip distances; ``FAR_CLIP`` must exceed any plane hit distance.
NEAR_CLIP = 0.01
FAR_CLIP = 10000.0

SCRIPT = "tools/make_scenes.py"

# Scene tables of paper_scenes.md: spheres (centre, radius, colour),
# planes (point, normal, colour) and lights (position, k).
FIG1_SPHERES = [
    ((-7.0, -5.0, -5.0), 5.5, (0.16, 0.62, 1.0)),
    ((3.4, -6.0, 3.0), 2.0, (0.38, 0.02, 1.0)),
    ((-5.0, 6.0, 6.9), 2.5, (1.0, 0.72, 0.26)),
    ((0.0, 0.0, 0.0), 2.5, (0.8, 0.7, 0.8)),
    ((-10.0, 0.0, 0.0), 5.5, (1.0, 0.77, 0.68)),
]
FIG1_PLANES = [
    ((0.0, 0.0, -10.0), (0.2, 0.5, 1.0), (0.7, 0.5, 1.0)),
    ((10.0, 0.0, -20.0), (1.0, 0.0, 1.0), (0.5, 0.5, 0.5)),
]
FIG1_LIGHTS = [
    ((10.0, 10.0, 10.0), 80.0),
    ((0.0, 10.0, 2.0), 70.0),
    ((-8.0, -8.0, 5.0), 65.0),
    ((10.0, 0.0, -2.0), 65.0),
]

FRACTION_SPHERES = [
    ((-0.5, 0.0, 0.0), 2.5, (0.2, 1.0, 0.0)),
    ((-10.0, 0.0, 0.0), 5.5, (0.0, 1.0, 0.5)),
]
FRACTION_PLANES = [
    ((0.0, -1.5, 0.0), (0.0, 1.0, 0.0), (0.7, 0.8, 0.2)),
    ((0.0, 3.5, 0.0), (0.0, -1.0, 0.0), (1.0, 0.8, 0.2)),
]
FRACTION_LIGHTS = [
    ((10.0, 10.0, 2.0), 50.0),
    ((10.0, 1.0, 0.0), 75.0),
    ((-4.0, 3.0, 0.0), 25.0),
]

TEST_COLOUR = (0.5, 0.3, 1.0)
TEST_PLANE = ((0.0, 0.0, 3.0), (0.0, 0.0, -1.0), (1.0, 1.0, 0.5))
LIGHTS_TEST_SPHERES = [
    ((0.0, 1.5, 0.0), 2.0, TEST_COLOUR),
    ((1.5, -1.25, 0.0), 2.0, TEST_COLOUR),
    ((-1.5, -1.25, 0.0), 2.0, TEST_COLOUR),
]

#: Index (in FIG1_SPHERES) of the radius-5.5 sphere made a perfect mirror in
#: paper_fig1_conductor.xml, chosen with ``tools/check_scenes.py
#: --mirror-study`` (report model at 400 x 400, numbers quoted below).
MIRROR_SPHERE = 4
MIRROR_REASON = [
    "Mirror: sphere_4 (centre (-10, 0, 0), radius 5.5), a conductor with",
    "material 'none' (reflectance 1). Of the two radius-5.5 spheres it is the",
    "one whose reflection shows more of the other objects: at 400 x 400 its",
    "reflected rays hit all four other spheres, in 3756 pixels (sphere_0 1390,",
    "sphere_2 1225, sphere_3 888, sphere_1 253), and a plane in 7282; a mirror",
    "sphere_0 (centre (-7, -5, -5)) would show three spheres in 1152 pixels",
    "(sphere_3 865, sphere_1 275, sphere_4 12) and a plane in 8547. Both",
    "reflect the black background in about 43 % of their pixels.",
]


def fmt(x):
    """Format a number compactly and deterministically.

    Parameters
    ----------
    x : float
        Value to format.

    Returns
    -------
    str
        ``x`` rounded to 9 decimals, up to 12 significant digits, without
        a trailing ``.0`` and with ``-0`` written as ``0``.
    """
    v = round(float(x), 9)
    if v == 0.0:
        v = 0.0
    return f"{v:.12g}"


def fmt3(v):
    """Format a 3-vector as ``"x, y, z"``.

    Parameters
    ----------
    v : sequence of float
        The three components.

    Returns
    -------
    str
        Comma separated components, each formatted by :func:`fmt`.
    """
    return ", ".join(fmt(c) for c in v)


def circle_points(n, radius, z):
    """Return the report's ``n`` points on a circle of the plane ``z``.

    Parameters
    ----------
    n : int
        Number of points.
    radius : float
        Circle radius.
    z : float
        Height of the circle's plane.

    Returns
    -------
    list of tuple of float
        ``(radius cos t_b, radius sin t_b, z)`` for ``b < n`` with
        ``t = linspace(0, 2 pi, n + 1)``.
    """
    t = np.linspace(0.0, 2.0 * math.pi, n + 1)[:n]
    return [(radius * math.cos(a), radius * math.sin(a), z) for a in t]


def header(title, lines, orbit=False):
    """Build the XML prolog and the header comment of a scene file.

    Parameters
    ----------
    title : str
        One-line description of the scene.
    lines : list of str
        Further comment lines (already indented as wanted).
    orbit : bool
        List the ``azimuth`` parameter of :func:`sensor`.

    Returns
    -------
    list of str
        Lines of the prolog and the comment.
    """
    out = [
        '<?xml version="1.0" encoding="utf-8"?>',
        "<!--",
        f"  Generated by {SCRIPT}; do not edit by hand (rerun the script).",
        f"  {title}",
    ]
    out += [f"  {s}" if s else "" for s in lines]
    out += [
        "",
        "  Parameters (override with mi.load_file(path, name=value)):",
        "    res         image width and height in pixels",
        "    spp         samples per pixel (1: one ray through each pixel centre)",
        "    integrator  integrator plugin; 'matte' is registered by mitsuba_mrt",
        "    jitter      jitter the stratified samples (false: pixel centres)",
    ]
    if orbit:
        out += [
            "    azimuth     camera angle about the vertical axis through the origin,",
            "                degrees (0: the report's view; 90: the camera on +x)",
        ]
    out += [
        "  Image row r, column c is the report's pixel (i, j) = (c, res - 1 - r).",
        "-->",
    ]
    return out


def sensor(eye_z, lines, orbit=False):
    """Append the camera, sampler and film of the report's eye.

    Parameters
    ----------
    eye_z : float
        z of the eye, ``+25`` (looking towards -z) or ``-25`` (towards +z).
    lines : list of str
        Output lines, extended in place.
    orbit : bool
        Turn the camera by ``$azimuth`` degrees about the world's y axis
        through the origin, after the lookat: the camera orbits the scene
        centre at the eye's distance, still looking at it.
    """
    fov = math.degrees(2.0 * math.atan(0.5 * WINDOW_SIZE / EYE_DISTANCE))
    lines += [
        "",
        '    <integrator type="$integrator"/>',
        "",
        '    <sensor type="perspective" id="camera">',
        f"        <!-- fov = 2 atan(({fmt(WINDOW_SIZE)} / 2) / {fmt(EYE_DISTANCE)}):"
        " the report's window of side W * s = 20 at z = 0 -->",
        '        <string name="fov_axis" value="x"/>',
        f'        <float name="fov" value="{fov:.9f}"/>',
        f'        <float name="near_clip" value="{fmt(NEAR_CLIP)}"/>',
        f'        <float name="far_clip" value="{fmt(FAR_CLIP)}"/>',
        '        <transform name="to_world">',
    ]
    if eye_z < 0:
        lines += [
            "            <!-- Mirror camera x: looking towards +z, a plain lookat puts",
            "                 world +x on the left of the image; the report has it on",
            "                 the right. -->",
            '            <scale x="-1"/>',
        ]
    lines += [
        f'            <lookat origin="0, 0, {fmt(eye_z)}" target="0, 0, 0"'
        ' up="0, 1, 0"/>',
    ]
    if orbit:
        lines += [
            "            <!-- Orbit: the eye turns about the y axis through the origin,",
            "                 still looking at it (azimuth 90 puts it on +x). -->",
            '            <rotate y="1" angle="$azimuth"/>',
        ]
    lines += [
        "        </transform>",
        '        <sampler type="stratified">',
        '            <integer name="sample_count" value="$spp"/>',
        '            <boolean name="jitter" value="$jitter"/>',
        "        </sampler>",
        '        <film type="hdrfilm">',
        '            <integer name="width" value="$res"/>',
        '            <integer name="height" value="$res"/>',
        '            <string name="pixel_format" value="rgb"/>',
        '            <string name="component_format" value="float32"/>',
        '            <rfilter type="box"/>',
        "        </film>",
        "    </sensor>",
    ]


def diffuse(colour, indent):
    """Return the lines of a diffuse BSDF of the given colour.

    Parameters
    ----------
    colour : sequence of float
        RGB reflectance.
    indent : str
        Leading whitespace of the ``<bsdf>`` element.

    Returns
    -------
    list of str
        The BSDF element.
    """
    return [
        f'{indent}<bsdf type="diffuse">',
        f'{indent}    <rgb name="reflectance" value="{fmt3(colour)}"/>',
        f"{indent}</bsdf>",
    ]


def shapes(spheres, planes, half_size, lines, mirror=None):
    """Append sphere and plane shapes, ids numbered in order.

    Parameters
    ----------
    spheres : list of tuple
        ``(centre, radius, colour)`` per sphere.
    planes : list of tuple
        ``(point, normal, colour)`` per plane.
    half_size : float
        Half side of the square rectangles standing in for the planes.
    lines : list of str
        Output lines, extended in place.
    mirror : int or None
        Index of a sphere to give a perfect mirror (``conductor``, material
        ``none``) instead of its diffuse BSDF.
    """
    n = 0
    for b, (centre, radius, colour) in enumerate(spheres):
        lines += ["", f'    <shape type="sphere" id="obj_{n}_sphere">']
        lines += [
            f'        <point name="center" value="{fmt3(centre)}"/>',
            f'        <float name="radius" value="{fmt(radius)}"/>',
        ]
        if b == mirror:
            lines += [
                f"        <!-- perfect mirror (reflectance 1); colour in the"
                f" report: {fmt3(colour)} -->",
                '        <bsdf type="conductor">',
                '            <string name="material" value="none"/>',
                "        </bsdf>",
            ]
        else:
            lines += diffuse(colour, "        ")
        lines += ["    </shape>"]
        n += 1
    for point, normal, colour in planes:
        nrm = np.asarray(normal, dtype=float)
        nrm = nrm / np.linalg.norm(nrm)
        # lookat maps the rectangle's +z normal onto (target - origin).
        target = np.asarray(point, dtype=float) + np.asarray(normal, dtype=float)
        up = "0, 0, 1" if abs(nrm[1]) > 0.9 else "0, 1, 0"
        lines += [
            "",
            f"    <!-- Infinite one-sided plane: point ({fmt3(point)}), unit normal"
            f" ({fmt3(np.round(nrm, 6))}).",
            f"         A {fmt(2 * half_size)} x {fmt(2 * half_size)} rectangle;"
            " lookat turns its +z normal towards target - origin. -->",
            f'    <shape type="rectangle" id="obj_{n}_plane">',
            '        <transform name="to_world">',
            f'            <scale value="{fmt(half_size)}"/>',
            f'            <lookat origin="{fmt3(point)}" target="{fmt3(target)}"'
            f' up="{up}"/>',
            "        </transform>",
        ]
        lines += diffuse(colour, "        ")
        lines += ["    </shape>"]
        n += 1


def emitters(lights, lines):
    """Append point lights of intensity ``pi * k``.

    Parameters
    ----------
    lights : list of tuple
        ``(position, k)`` per light.
    lines : list of str
        Output lines, extended in place.
    """
    for b, (position, k) in enumerate(lights):
        lines += [
            "",
            f'    <emitter type="point" id="light_{b}">',
            f"        <!-- report strength k = {fmt(k)}; intensity = pi * k -->",
            f'        <point name="position" value="{fmt3(position)}"/>',
            f'        <rgb name="intensity" value="{fmt(math.pi * k)}"/>',
            "    </emitter>",
        ]


def scene(title, notes, res, eye_z, spheres, planes, lights, plane_half_size,
          mirror=None, orbit=False):
    """Build the complete text of one scene file.

    Parameters
    ----------
    title : str
        One-line description for the header comment.
    notes : list of str
        Further header comment lines.
    res : int
        Default image resolution.
    eye_z : float
        z of the eye (``+25`` or ``-25``).
    spheres, planes, lights : list of tuple
        Scene content, see :func:`shapes` and :func:`emitters`.
    plane_half_size : float
        Half side of the plane rectangles, see :func:`shapes`.
    mirror : int or None
        Sphere made a perfect mirror, see :func:`shapes`.
    orbit : bool
        A ``$azimuth`` parameter (default 0) orbits the camera, see :func:`sensor`.

    Returns
    -------
    str
        The XML document, ending with a newline.
    """
    lines = header(title, notes, orbit)
    lines += [
        '<scene version="3.0.0">',
        f'    <default name="res" value="{res}"/>',
        '    <default name="spp" value="1"/>',
        '    <default name="integrator" value="matte"/>',
        '    <default name="jitter" value="false"/>',
    ]
    if orbit:
        lines += ['    <default name="azimuth" value="0"/>']
    sensor(eye_z, lines, orbit)
    shapes(spheres, planes, plane_half_size, lines, mirror)
    emitters(lights, lines)
    lines += ["</scene>", ""]
    return "\n".join(lines)


def scene_specs():
    """Return the description of every scene of the report.

    Returns
    -------
    dict
        File name -> keyword arguments of :func:`scene` (``title``,
        ``notes``, ``res``, ``eye_z``, ``spheres``, ``planes``, ``lights``,
        ``plane_half_size``, ``mirror``, optionally ``orbit``), in a fixed order.
        ``tools/check_scenes.py`` uses the same description for its analytic
        reference.
    """
    specs = {}
    fig1_notes = [
        "Report: Fig. 1 (the example, 400 x 400, s = 0.05) and Figs. 2-5 built",
        "on it; also the pixels test (Fig. 8, Fig. C): res = int(400 a) for",
        "a = 0.5, 0.75, ..., 3.0 (the view is the same at every res).",
        "5 spheres, 2 planes, 4 lights; eye (0, 0, +25) looking towards -z.",
    ]
    fig1 = dict(res=400, eye_z=EYE_DISTANCE, spheres=FIG1_SPHERES,
                planes=FIG1_PLANES, lights=FIG1_LIGHTS,
                plane_half_size=PLANE_HALF_SIZE, mirror=None, orbit=False)
    specs["paper_fig1.xml"] = dict(
        fig1, title="Scene of the report's Fig. 1.", notes=fig1_notes)
    specs["paper_fig1_orbit.xml"] = dict(
        fig1, orbit=True,
        title="Fig. 1 scene seen from a camera orbiting its centre (not in the report).",
        notes=fig1_notes[-1:] + [
            "At azimuth 0 (the default) it is paper_fig1.xml.  An orbit is a batch:",
            "python -m mitsuba_mrt batch scenes_xml/paper_fig1_orbit.xml -o out/orbit",
            "    -D azimuth=-60:121:15 -D res=200",
            "Between about -60 and 120 degrees the camera sees the planes' lit",
            "side; from about 150 to 270 their black backs (the report's planes",
            "are one-sided) fill the view."])
    specs["paper_fig1_conductor.xml"] = dict(
        fig1, mirror=MIRROR_SPHERE,
        title="Fig. 1 scene with one sphere a perfect mirror (not in the report).",
        notes=fig1_notes[-1:] + [""] + MIRROR_REASON)
    specs["paper_fraction.xml"] = dict(
        title="Scene of the report's fraction and filter tests.",
        notes=["Report: Fig. 6 and Fig. A (sampling fraction f = 0.025 ... 0.25),",
               "Fig. 7 and Fig. B (filter sigma and cutoff); 200 x 200, s = 0.1.",
               "2 spheres, 2 planes, 3 lights; eye (0, 0, +25) looking towards -z.",
               "The planes reach the horizon; their 4000 x 4000 rectangles cover",
               "every pixel up to res 231 (beyond, a few central rows, lit ~1e-6,",
               "show background instead of a plane)."],
        res=200, eye_z=EYE_DISTANCE, spheres=FRACTION_SPHERES,
        planes=FRACTION_PLANES, lights=FRACTION_LIGHTS,
        plane_half_size=FRACTION_PLANE_HALF_SIZE, mirror=None)
    for n in range(11):
        specs[f"paper_objects_{n}.xml"] = dict(
            title=f"Scene of the report's objects test with N = {n} spheres.",
            notes=["Report: Fig. 9 and Fig. D (N = 0, 1, ..., 10); 200 x 200, s = 0.1.",
                   "Spheres of radius 2 at (8 cos t_b, 8 sin t_b, 1),",
                   "t = linspace(0, 2 pi, N + 1), b < N; 1 plane, 1 light;",
                   "eye (0, 0, -25) looking towards +z."],
            res=200, eye_z=-EYE_DISTANCE,
            spheres=[(c, 2.0, TEST_COLOUR) for c in circle_points(n, 8.0, 1.0)],
            planes=[TEST_PLANE], lights=[((0.0, 0.0, -5.0), 70.0)],
            plane_half_size=PLANE_HALF_SIZE, mirror=None)
    for n in range(1, 20, 2):
        specs[f"paper_lights_{n}.xml"] = dict(
            title=f"Scene of the report's lights test with N = {n} lights.",
            notes=["Report: Fig. 10 and Fig. E (N = 1, 3, ..., 19); 200 x 200,"
                   " s = 0.1.",
                   "Lights of k = 20 at (8 cos t_b, 8 sin t_b, -4),",
                   "t = linspace(0, 2 pi, N + 1), b < N; 3 spheres, 1 plane;",
                   "eye (0, 0, -25) looking towards +z."],
            res=200, eye_z=-EYE_DISTANCE, spheres=LIGHTS_TEST_SPHERES,
            planes=[TEST_PLANE],
            lights=[(p, 20.0) for p in circle_points(n, 8.0, -4.0)],
            plane_half_size=PLANE_HALF_SIZE, mirror=None)
    return specs


def all_scenes():
    """Return the XML text of every scene of the report.

    Returns
    -------
    dict
        File name -> XML text, in the order of :func:`scene_specs`.
    """
    return {name: scene(**spec) for name, spec in scene_specs().items()}


def main():
    """Write every scene file into the output folder."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent.parent
                                             / "scenes_xml"),
                        help="output folder (default: scenes_xml/ of the repo)")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    scenes = all_scenes()
    for name, text in scenes.items():
        (out / name).write_text(text, encoding="utf-8", newline="\n")
    print(f"wrote {len(scenes)} scene files to {out}")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Check the scene files of ``scenes_xml/`` against the report's model.

For every scene written by ``tools/make_scenes.py`` this script loads the
XML file with Mitsuba (variant ``llvm_ad_rgb``) at a small resolution and
compares it with an analytic numpy evaluation of the report's ray-tracer,
built from the same scene tables (``make_scenes.scene_specs``):

1. the scene loads and its ``direct`` render has no NaN or Inf;
2. geometry and orientation: the shape seen at every pixel (Mitsuba's
   ``aov`` integrator, ``shape_index``, mapped back to the shape ids
   ``obj_<n>_sphere`` / ``obj_<n>_plane``) equals the first object hit by the
   report's camera ray of pixel ``(i, j) = (c, res - 1 - r)``, for at least
   99.5 % of the pixels and for every pixel away from silhouettes, at the
   check resolution and at the scene's default one;
3. shading: at every pixel away from silhouettes and shadow boundaries the
   ``direct`` render equals ``colour * sum_k k max(0, n.l) / d^2`` over the
   unshadowed lights (before the report's clipping), to a relative 1e-3.
   ``direct`` picks one emitter per sample (with weight N lights) from the
   sampler's next 1D sample, which with ``spp=1, jitter=false`` is 0.5 at
   every pixel: the plain render is N times the contribution of one fixed
   light.  The reference is therefore the sum of one render per light, each
   of a copy of the scene holding that light only (deterministic: point
   lights are delta lights).

With ``--mirror-study`` it instead compares the two choices of mirror sphere
for ``paper_fig1_conductor.xml`` (see ``make_scenes.MIRROR_SPHERE``).

Usage::

    python tools/check_scenes.py [--res 64] [--mirror-study]

Exit status 0 when every scene passes.  The files must also be up to date:
each is compared byte for byte with the output of ``make_scenes.py``.
"""

import argparse
import copy
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import make_scenes as ms  # noqa: E402

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

mi.set_variant("llvm_ad_rgb")

REPO = Path(__file__).resolve().parent.parent
SCENES = REPO / "scenes_xml"
#: Minimum fraction of pixels whose visible shape must agree.
MIN_ID_AGREEMENT = 0.995
#: Relative and absolute tolerance of the shading comparison.
RTOL, ATOL = 1e-3, 1e-6


# ----------------------------------------------------------------------------
# Analytic model of the report (numpy, float64)
# ----------------------------------------------------------------------------

def objects(spec):
    """List the scene's objects in shape-id order.

    Parameters
    ----------
    spec : dict
        A scene description of ``make_scenes.scene_specs``.

    Returns
    -------
    list of tuple
        ``("sphere", centre, radius, colour)`` then
        ``("plane", point, unit_normal, colour)``, arrays as float64.
    """
    out = [("sphere", np.array(c, float), float(r), np.array(col, float))
           for c, r, col in spec["spheres"]]
    for p, n, col in spec["planes"]:
        n = np.array(n, float)
        out.append(("plane", np.array(p, float), n / np.linalg.norm(n),
                    np.array(col, float)))
    return out


def intersect(obj, o, d, tmin):
    """Ray parameters of the first intersection with one object.

    Parameters
    ----------
    obj : tuple
        An entry of :func:`objects`.
    o, d : ndarray, shape (..., 3)
        Ray origins and (not necessarily unit) directions.
    tmin : float or ndarray
        Smallest accepted ray parameter.

    Returns
    -------
    ndarray, shape (...)
        Ray parameter ``t`` of the hit (point ``o + t d``), ``inf`` if none.
    """
    if obj[0] == "sphere":
        _, c, r, _ = obj
        oc = o - c
        a = np.sum(d * d, -1)
        b = np.sum(oc * d, -1)
        cc = np.sum(oc * oc, -1) - r * r
        disc = b * b - a * cc
        sq = np.sqrt(np.maximum(disc, 0.0))
        t1, t2 = (-b - sq) / a, (-b + sq) / a
        t = np.where(t1 > tmin, t1, np.where(t2 > tmin, t2, np.inf))
        return np.where(disc >= 0.0, t, np.inf)
    _, p, n, _ = obj
    den = np.sum(d * n, -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.sum((p - o) * n, -1) / den
    return np.where((np.abs(den) > 1e-300) & (t > tmin), t, np.inf)


def report_render(spec, res):
    """Evaluate the report's matte ray-tracer at every pixel centre.

    Parameters
    ----------
    spec : dict
        A scene description of ``make_scenes.scene_specs``.
    res : int
        Image width and height ``W``; the pixel size is ``20 / W``.

    Returns
    -------
    ids : ndarray of int, shape (res, res)
        Index of the first object hit (-1: background), indexed ``[j, i]``
        (report row ``j``, 0 at the bottom; column ``i``).
    colour : ndarray, shape (res, res, 3)
        ``colour * E`` before clipping.
    vis : ndarray of int, shape (res, res)
        Bit ``b`` set when light ``b`` is unshadowed (``n.l > 0``).
    """
    objs = objects(spec)
    s = ms.WINDOW_SIZE / res
    x = s * (np.arange(res) - (res - 1) / 2.0)
    X, Y = np.meshgrid(x, x, indexing="xy")  # [j, i]
    eye = np.array([0.0, 0.0, spec["eye_z"]])
    d = np.stack([X, Y, np.full_like(X, -spec["eye_z"])], -1)
    ts = np.stack([intersect(ob, eye, d, 1e-9) for ob in objs] or
                  [np.full(X.shape, np.inf)], -1)
    ids = np.where(np.isfinite(ts.min(-1)), ts.argmin(-1), -1)
    t = np.where(ids >= 0, ts.min(-1), 0.0)
    p = eye + t[..., None] * d
    normal = np.zeros_like(p)
    albedo = np.zeros_like(p)
    for k, ob in enumerate(objs):
        m = ids == k
        normal[m] = (p[m] - ob[1]) / ob[2] if ob[0] == "sphere" else ob[2]
        albedo[m] = ob[3]
    irr = np.zeros(X.shape)
    vis = np.zeros(X.shape, dtype=np.int64)
    for b, (pos, k) in enumerate(spec["lights"]):
        to_l = np.asarray(pos, float) - p
        dist2 = np.sum(to_l * to_l, -1)
        cos = np.sum(normal * to_l, -1) / np.sqrt(dist2)
        lit = (ids >= 0) & (cos > 0.0)
        for ob in objs:  # shadow ray p -> light, parameter in (eps, 1 - eps)
            th = intersect(ob, p, to_l, 1e-7)
            lit &= ~(th < 1.0 - 1e-7)
        irr += np.where(lit, k * cos / dist2, 0.0)
        vis |= lit.astype(np.int64) << b
    return ids, albedo * irr[..., None], vis


def uniform_3x3(a):
    """Mask of pixels whose 3 x 3 neighbourhood holds one value.

    Parameters
    ----------
    a : ndarray, shape (H, W)
        Label image.

    Returns
    -------
    ndarray of bool, shape (H, W)
        True where all 9 neighbours (image borders excluded) equal the pixel.
    """
    out = np.zeros(a.shape, bool)
    c = a[1:-1, 1:-1]
    m = np.ones(c.shape, bool)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            m &= a[1 + dy:a.shape[0] - 1 + dy, 1 + dx:a.shape[1] - 1 + dx] == c
    out[1:-1, 1:-1] = m
    return out


# ----------------------------------------------------------------------------
# Mitsuba side
# ----------------------------------------------------------------------------

def mitsuba_ids(scene):
    """Render the index of the visible shape at every pixel.

    Parameters
    ----------
    scene : mitsuba.Scene
        A loaded scene (spp 1, no jitter: one ray per pixel centre).

    Returns
    -------
    ndarray of int, shape (H, W)
        Image rows (row 0 at the top) of the ``n`` of the ``*_<n>`` id of
        the shape seen, -1 for background.  ``scene.shapes()`` is *not* in
        file order, hence the mapping through the shape ids.
    """
    aov = mi.load_dict({"type": "aov", "aovs": "si:shape_index"})
    raw = np.array(mi.render(scene, integrator=aov))[..., -1]
    regs = np.array(dr.reinterpret_array(mi.UInt32, scene.shapes_dr()))
    lut = {0: -1}
    for reg, shape in zip(regs, scene.shapes()):
        lut[int(reg)] = int(shape.id().split("_")[1])  # obj_<k>_<kind>
    return np.vectorize(lambda v: lut.get(int(v), -2))(raw)


def single_light_sum(path, res):
    """Sum of ``direct`` renders of one-light copies of a scene.

    Parameters
    ----------
    path : Path
        Scene file.
    res : int
        Resolution.

    Returns
    -------
    ndarray, shape (res, res, 3)
        Deterministic direct illumination from all the point lights.
    """
    tree = ET.parse(path)
    root = tree.getroot()
    emitters = root.findall("emitter")
    total = np.zeros((res, res, 3))
    for keep in range(len(emitters)):
        r = copy.deepcopy(root)
        for b, e in enumerate(r.findall("emitter")):
            if b != keep:
                r.remove(e)
        scene = mi.load_string(ET.tostring(r, encoding="unicode"),
                               integrator="direct", res=res)
        total += np.array(mi.render(scene, spp=1), dtype=np.float64)
    return total


def compare_ids(scene, spec, res, problems, tag):
    """Compare the visible shapes of Mitsuba and of the report model.

    Parameters
    ----------
    scene : mitsuba.Scene
        The scene loaded at resolution ``res``.
    spec : dict
        Its description from ``make_scenes.scene_specs``.
    res : int
        Resolution.
    problems : list of str
        Failures are appended here.
    tag : str
        Prefix of the failure messages.

    Returns
    -------
    same : ndarray of bool, shape (res, res)
        Pixels (image rows) where both see the same shape.
    mirrored : float
        Agreement had the image been mirrored left-right (orientation
        sensitivity of the scene; 100 % for left-right symmetric scenes).
    """
    ids_r = report_render(spec, res)[0][::-1]  # image row r = report row res-1-r
    ids_m = mitsuba_ids(scene)
    same = ids_m == ids_r
    if same.mean() < MIN_ID_AGREEMENT:
        problems.append(f"{tag}ids agree on {same.mean():.2%} only")
    inner_diff = np.sum(~same & uniform_3x3(ids_r))
    if inner_diff:
        problems.append(f"{tag}{inner_diff} ids differ away from edges")
    return same, (ids_m[:, ::-1] == ids_r).mean()


def check(name, spec, res):
    """Run the three checks on one scene file.

    Parameters
    ----------
    name : str
        File name in ``scenes_xml/``.
    spec : dict
        Its description from ``make_scenes.scene_specs``.
    res : int
        Resolution of the checks; the shape ids are also compared at the
        scene's default resolution.

    Returns
    -------
    bool
        True when every check passes; a one-line summary is printed.
    """
    path = SCENES / name
    problems = []
    scene = mi.load_file(str(path), integrator="direct", res=res)
    img = np.array(mi.render(scene, spp=1))
    light_sum = single_light_sum(path, res)
    if not (np.all(np.isfinite(img)) and np.all(np.isfinite(light_sum))):
        problems.append("NaN/Inf in render")

    # 2. geometry and orientation, at the check and the default resolution.
    same, mirrored = compare_ids(scene, spec, res, problems, "")
    full = mi.load_file(str(path), integrator="direct")
    same_full, _ = compare_ids(full, spec, spec["res"], problems,
                               f"at res {spec['res']}: ")

    # 3. shading, away from silhouettes and shadow boundaries.
    ids_r, col_r, vis_r = (a[::-1] for a in report_render(spec, res))
    mask = uniform_3x3(ids_r) & uniform_3x3(vis_r) & same
    if spec["mirror"] is not None:
        mask &= ids_r != spec["mirror"]
    a, b = light_sum[mask], col_r[mask]
    bad = np.abs(a - b) > RTOL * np.abs(b) + ATOL
    lit = b > 1e-2
    rel = np.max(np.abs(a - b)[lit] / b[lit]) if lit.any() else 0.0
    if bad.any():
        problems.append(f"shading differs at {np.any(bad, -1).sum()} px")
    if mask.sum() < 20:
        problems.append(f"only {mask.sum()} pixels for the shading check")

    status = "PASS" if not problems else "FAIL"
    print(f"{status} {name:25s} ids {same.mean():7.2%}, at res {spec['res']}"
          f" {same_full.mean():7.2%} ({np.sum(~same_full):3d} px differ;"
          f" mirrored {mirrored:6.1%})  shading: {mask.sum():4d} px"
          f" ({int(lit.any(-1).sum()):4d} lit), max rel err {rel:.1e}"
          + ("" if not problems else "  <- " + "; ".join(problems)))
    return not problems


# ----------------------------------------------------------------------------
# Mirror study for paper_fig1_conductor.xml
# ----------------------------------------------------------------------------

def mirror_study(res=400, out_dir=Path("/tmp")):
    """Compare the two radius-5.5 spheres of Fig. 1 as the mirror.

    For each candidate, count the pixels that see the candidate and what
    their reflected ray hits first (report model, numpy), and write a
    ``path``-traced image of the scene with that sphere a mirror.

    Parameters
    ----------
    res : int
        Resolution of the study.
    out_dir : Path
        Folder for the ``mirror_sphere_<n>.exr`` / ``.png`` images.
    """
    spec = ms.scene_specs()["paper_fig1.xml"]
    objs = objects(spec)
    ids, _, _ = report_render(spec, res)
    s = ms.WINDOW_SIZE / res
    x = s * (np.arange(res) - (res - 1) / 2.0)
    X, Y = np.meshgrid(x, x, indexing="xy")
    eye = np.array([0.0, 0.0, spec["eye_z"]])
    d = np.stack([X, Y, np.full_like(X, -spec["eye_z"])], -1)
    for cand in [b for b, (_, r, _) in enumerate(spec["spheres"]) if r == 5.5]:
        m = ids == cand
        dd = d[m]
        t = intersect(objs[cand], eye, dd, 1e-9)
        p = eye + t[:, None] * dd
        n = (p - objs[cand][1]) / objs[cand][2]
        refl = dd - 2.0 * np.sum(dd * n, -1)[:, None] * n
        ts = np.stack([intersect(ob, p, refl, 1e-7) if k != cand
                       else np.full(len(p), np.inf) for k, ob in enumerate(objs)], -1)
        hit = np.where(np.isfinite(ts.min(-1)), ts.argmin(-1), -1)
        counts = {k: int(np.sum(hit == k)) for k in range(-1, len(objs))}
        spheres = sum(v for k, v in counts.items() if 0 <= k < len(spec["spheres"]))
        print(f"mirror sphere_{cand}: {m.sum()} px visible; reflected ray hits "
              + ", ".join(f"{'background' if k < 0 else ms_id(spec, k)} {v}"
                          for k, v in counts.items() if v)
              + f"; other spheres in total {spheres} px")
        xml = ms.scene(**dict(spec, mirror=cand))
        scene = mi.load_string(xml, integrator="path", res=res)
        img = mi.render(scene, spp=16)
        bmp = mi.Bitmap(img)
        bmp.write(str(out_dir / f"mirror_sphere_{cand}.exr"))
        bmp.convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.UInt8,
                    srgb_gamma=True).write(str(out_dir / f"mirror_sphere_{cand}.png"))
    print(f"images written to {out_dir}/mirror_sphere_*.png")


def ms_id(spec, k):
    """Return the shape id of object ``k`` (``sphere_<k>`` or ``plane_<k>``)."""
    return f"obj_{k}_sphere" if k < len(spec["spheres"]) else f"obj_{k}_plane"


def main():
    """Check every scene; exit status 1 when any check fails."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--res", type=int, default=64,
                        help="resolution of the checks (default 64)")
    parser.add_argument("--mirror-study", action="store_true",
                        help="compare the two mirror choices instead")
    args = parser.parse_args()
    if args.mirror_study:
        mirror_study()
        return
    t0 = time.time()
    specs = ms.scene_specs()
    ok = True
    for name, spec in specs.items():
        if (SCENES / name).read_text(encoding="utf-8") != ms.scene(**spec):
            print(f"FAIL {name}: file differs from make_scenes.py output (rerun it)")
            ok = False
            continue
        ok &= check(name, spec, args.res)
    print(f"{'ALL PASS' if ok else 'SOME FAILED'}: {len(specs)} scenes at res"
          f" {args.res} in {time.time() - t0:.1f} s")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()

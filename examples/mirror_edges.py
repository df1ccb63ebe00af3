"""Error on the edges of a curved mirror's reflections against direct edges.

    python examples/mirror_edges.py --res 400 --modes fast,idpass,refine

Edges are the pixels whose exact id (shape chain along mirror bounces, and
visible lights) differs from a 4-neighbour's, taken from a full trace; the
mean error (the report's metric, per pixel) is reported on the edges inside
the mirror (``obj_4_sphere`` of ``paper_fig1_conductor.xml``) and outside it,
with the share of pixels each mode traced.
"""

import argparse

import mitsuba_mrt
from mitsuba_mrt.recon.metrics import edge_mask, error_map
from mitsuba_mrt.renderer.scene_query import ordered_shapes


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="scenes_xml/paper_fig1_conductor.xml")
    parser.add_argument("--mirror", default="obj_4_sphere", help="id of the mirror shape")
    parser.add_argument("--res", type=int, default=400)
    parser.add_argument("--modes", default="fast,idpass,refine")
    args = parser.parse_args()

    variant = mitsuba_mrt.activate("auto")
    scene = mitsuba_mrt.load_scene(args.scene, res=args.res)
    mirror = 1 + [s.id() for s in ordered_shapes(scene)].index(args.mirror)
    reference, _ = mitsuba_mrt.render_reference(scene)
    full = mitsuba_mrt.render(scene, mode="paper", sample_fraction=1.0)
    height, width = reference.shape[:2]
    ids = full.trace.ids("exact").reshape(height, width)
    edge = edge_mask(ids)
    in_mirror = full.trace.shape_index.reshape(height, width) == mirror
    print(f"{args.scene} {width}x{height} [{variant}]: {int((edge & in_mirror).sum())} edge "
          f"pixels in the mirror, {int((edge & ~in_mirror).sum())} outside")
    print(f"{'mode':8s} {'mirror edges':>13s} {'direct edges':>13s} {'all pixels':>11s} "
          f"{'traced':>7s}")
    for mode in args.modes.split(","):
        result = mitsuba_mrt.render(scene, mode=mode)
        err = error_map(result.image, reference)
        print(f"{mode:8s} {err[edge & in_mirror].mean():13.6f} {err[edge & ~in_mirror].mean():13.6f} "
              f"{err.mean():11.6f} {result.traced_mask.mean():7.3f}")


if __name__ == "__main__":
    main()

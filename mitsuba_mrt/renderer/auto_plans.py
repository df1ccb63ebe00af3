"""``auto``'s outcome, and the MRT plans a scene's kind points to.

Under the default target, without a pilot, :func:`unmeasured_plan` reads
the scene's kind (its lights, surfaces and the image's size) and points to
:data:`HOME` (mode ``idpass``, its grid denoised) or :data:`SKY` (mode
``refine``, its grid denoised), or to neither (the passes);
:func:`mrt_by_kind` makes that plan, its image to be checked
(:func:`keeps`).  Without OIDN the plan is :data:`PLAIN` (mode ``idpass``,
undenoised) or :data:`PLAIN_EDGES` (``refine``), checked too
(:func:`plain_plan`).  :class:`AutoOutcome` is what every path of
:func:`~.auto.run_auto` returns.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import NamedTuple

import mitsuba as mi
import numpy as np

from ..modes.plan import Candidate, Plan
from ..recon.ids import edge_share
from ..recon.sampling import every_pixel
from ..types import MRTParams, SeedStream, SparseTrace
from .held_out import HeldOut
from .progressive import Progress
from .scene_query import (environment_map, lit_diffuse_by_points, textured_diffuse_shapes,
                          transmits)
from .trace import trace_shapes

#: The plan, under the default target, where every surface is diffuse and
#: every light a point, spot or directional one
#: (:func:`~.scene_query.lit_diffuse_by_points`, the report's own scenes):
#: mode ``idpass`` at the scene's spp, OIDN on its grid.  There its ids hold
#: every edge of shape and shadow and its error meets a full render's noise
#: for less than the denoised passes take (``bench rival``'s Fig. 1 row).
HOME = Candidate("idpass+oidn", "mrt", 0, mode="idpass", denoise=True)
HOME_REASON = "diffuse surfaces lit by point lights alone: the MRT's id pass, denoised grid"
#: The fewest spp for :data:`HOME`: below them the id pass costs too large a
#: share of the render, and the passes' few rounds cost little.
HOME_MIN_SPP = 16
#: :data:`HOME` on other scenes, under the same conditions: images of at least
#: this many pixels (512 x 512) lit by no environment map
#: (:func:`~.scene_query.environment_map`) where no surface transmits light
#: (:func:`~.scene_query.transmits`: glass shows the scene behind it, which no
#: id tells apart; ``bench rival`` at 512 px: ``idpass+oidn`` 1.10-1.12x the
#: alternative's error on ``cornell`` and ``room``).  There the grid resolves
#: the shading the ids do not hold, and the id pass's albedo the textures that
#: OIDN blurs; on smaller images the grid's spacing is coarse beside the
#: scene's detail (``bench rival`` at 256 px: ``idpass+oidn`` behind the
#: alternative on five of nine gallery scenes).
WIDE_PIXELS = 1 << 18
WIDE_REASON = ("512 x 512 pixels or more, no environment map, no glass: the MRT's id pass, "
               "denoised grid")
#: :data:`HOME` on a smaller image where a diffuse surface is textured
#: (:func:`~.scene_query.textured_diffuse_shapes`) and no surface transmits
#: light (:func:`~.scene_query.transmits`): the id pass gives the texture at
#: every pixel and the grid only the shading beneath it, which is smooth.
#: Through glass the ids see one shape where an image of the scene lies
#: (``room`` at 256 px: the check rejects ``idpass+oidn``, then the passes).
TEXTURED_REASON = ("textured diffuse surfaces, nothing transmits light: the MRT's id pass "
                   "gives the texture, denoised grid")
#: The reasons whose plan gives way to the passes where too many of the
#: image's pixels lie at an edge between ids (:func:`edge_tested`).
EDGE_TESTED = (WIDE_REASON, TEXTURED_REASON)
#: :data:`HOME` on such an image is traced only where at most this share of
#: its pixels lie at an edge between shapes, then between ids
#: (:func:`~mitsuba_mrt.recon.ids.edge_share` of the id pass, which
#: ``idpass`` then reuses): where more do, the regions are small beside the
#: grid's spacing and hold few of its samples each (``bench rival`` at 512
#: px against converged renders of 2048 spp: of the gallery scenes without
#: glass or an environment map, ``instanced``, 5.5 %, is the one where
#: ``idpass+oidn`` is no better than the alternative, 1.02x; the others have
#: 1.1-3.6 % and 0.61-0.96x).
WIDE_EDGE_SHARE = 0.045
#: The same share on a smaller image (:data:`TEXTURED_REASON`), whose grid is
#: coarser beside the scene (``bench rival`` at 256 px against converged
#: renders of 4096 spp: ``idpass+oidn`` at 0.70x and 0.93x the alternative's
#: error with 2.2 % and 2.4 % of the pixels at an edge, 1.18x with 3.1 %).
SMALL_EDGE_SHARE = 0.027
#: The plan, on images of :data:`WIDE_PIXELS` or more, where an environment
#: map lights the scene: mode ``refine``, OIDN on its grid.  Light from every
#: direction shades the inside of a shape slowly, which the grid holds; where
#: it does not, at the shapes' edges and their reflections of the map,
#: ``refine`` traces the pixels.  On smaller images, as under mirrors or
#: glass there, the passes (``bench rival`` at 256 px against converged
#: renders of 4096 spp: ``refine+oidn`` 1.07-1.14x the alternative's error on
#: ``envmap_objects``, ``materials`` and ``cornell``).
SKY = Candidate("refine+oidn", "mrt", 0, mode="refine", denoise=True)
SKY_REASON = "an environment map's light: the MRT's refined edges, denoised grid"
#: The plan under the default target where OIDN is not installed, on scenes
#: lit by no environment map where no surface transmits light
#: (:func:`plain_plan`): mode ``idpass`` at the scene's spp, undenoised.  Its
#: id pass gives every pixel its surface and texture, its grid (smoothed
#: within its noise) the shading between; a full render at as few spp as fit
#: its time is far noisier (``bench rival --no-oidn``).
PLAIN = Candidate("idpass", "mrt", 0, mode="idpass", denoise=False)
PLAIN_REASON = ("no denoiser installed: the MRT's id pass, its grid smoothed within the "
                "noise")
#: ... and through glass or under an environment map: mode ``refine``,
#: undenoised, which traces the pixels whose light the grid cannot follow
#: (the ids see one surface where glass shows the scene behind it, and the
#: id pass's image there is twice a full render's noise and more, which
#: its check finds after it has cost a fifth of a full render).
PLAIN_EDGES = Candidate("refine", "mrt", 0, mode="refine", denoise=False)
PLAIN_EDGES_REASON = ("no denoiser installed, glass or an environment map: the MRT's "
                      "refined edges, its grid smoothed within the noise")
#: :data:`HOME`'s, :data:`SKY`'s and :data:`PLAIN`'s image is kept where its
#: held-out check estimates its RMS error at most this many times a full
#: render's noise (the default target); else the passes (without OIDN, the
#: full render) render the image.  The RMS error weighs the MRT's few
#: pixels at edges more than the report's mean absolute error does, so an
#: image that meets the target by the report's metric may have an RMS error
#: above the noise (``examples/held_out_check.py``).
CHECK_SLACK = 1.5
#: :data:`HOME`'s plan on scenes other than the report's kind, on images of
#: fewer than :data:`WIDE_PIXELS` (:data:`TEXTURED_REASON`): the grid spreads
#: the same samples over this many times the pixels (``sample_fraction``),
#: at that share of the spp.  There the default grid's spacing is coarse
#: beside the scene's detail (``examples/grid_spread.py``).
SMALL_IMAGE_SPREAD = 2


@dataclass
class AutoOutcome:
    """``auto``'s plan, and the image when the passes made it (``grid``: the
    preview's grid, where tracing it told the plan, and what its launch spent
    recording its kernels, ``grid_recording_s``; ``check``: the plan's
    MRT image is to be checked, :func:`keeps`; ``id_pass``: the image's id
    pass, where the plan traced it; ``preview_key``: a preview's key, under
    which :func:`~.auto_limit.note_preview_after` keeps what its later stages take;
    ``kept_key``: a kept plan's key (:mod:`.kept_plans`), under which
    :func:`~.kept_plans.note_render` keeps what its render took)."""

    plan: Plan
    image: np.ndarray | None = None
    alpha: np.ndarray | None = None
    progress: Progress | None = None
    grid: SparseTrace | None = None
    check: bool = False
    id_pass: SparseTrace | None = None
    preview_key: tuple | None = None
    kept_key: tuple | None = None
    grid_recording_s: float = 0.0


def keeps(held: HeldOut) -> bool:
    """Whether an MRT image chosen without a pilot (:data:`HOME`, :data:`SKY`)
    whose check found ``held`` is kept.

    Examples
    --------
    >>> keeps(HeldOut(error=0.012, full_error=0.01, pixels=2048, seconds=0.01))
    True
    >>> keeps(HeldOut(error=0.02, full_error=0.01, pixels=2048, seconds=0.01))
    False
    """
    return held.error <= CHECK_SLACK * held.full_error


def unmeasured_plan(scene: mi.Scene, pixels: int) -> tuple[Candidate, str] | None:
    """The MRT plan the scene's kind and ``pixels`` point to (:data:`HOME`,
    :data:`SKY`), with its reason, or None: the passes."""
    if lit_diffuse_by_points(scene):
        return HOME, HOME_REASON
    if pixels >= WIDE_PIXELS and environment_map(scene):
        return SKY, SKY_REASON
    if pixels >= WIDE_PIXELS and not transmits(scene):
        return HOME, WIDE_REASON
    if (not environment_map(scene) and not transmits(scene)
            and textured_diffuse_shapes(scene).any()):
        return HOME, TEXTURED_REASON
    return None


def plain_plan(scene: mi.Scene) -> tuple[Candidate, str]:
    """The MRT plan without OIDN, and its reason: :data:`PLAIN` where no
    environment map lights the scene (:func:`~.scene_query.environment_map`)
    and nothing transmits light (:func:`~.scene_query.transmits`), else
    :data:`PLAIN_EDGES`."""
    if not environment_map(scene) and not transmits(scene):
        return PLAIN, PLAIN_REASON
    return PLAIN_EDGES, PLAIN_EDGES_REASON


def mrt_by_kind(scene, tracer, params: MRTParams, width: int, height: int, notes: list,
                 probe_start: float) -> tuple[AutoOutcome | None, Traced]:
    """(the outcome of :func:`unmeasured_plan`'s MRT plan, its image to be
    checked, or None: the passes; what the plan traced of every pixel).  A
    large or textured image's plan (:data:`EDGE_TESTED`) gives way to the
    passes, with a note, where too many of its pixels lie at an edge between
    ids (:func:`edge_tested`)."""
    chosen = unmeasured_plan(scene, width * height)
    if chosen is None:
        return None, Traced()
    traced = Traced()
    if chosen[1] in EDGE_TESTED:
        traced, too_many = edge_tested(scene, tracer, params, width, height, notes)
        if too_many:
            return None, traced
    id_pass = traced.id_pass  # (a trace of the image: not the plan's time)
    pilot_s = time.perf_counter() - probe_start - (0.0 if id_pass is None else id_pass.seconds)
    choice = spread(chosen[0], chosen[1], tracer.spp, params.sample_fraction, width * height)
    return AutoOutcome(Plan(choice, chosen[1], pilot_s=pilot_s, notes=notes), check=True,
                       id_pass=id_pass), traced


def spread(chosen: Candidate, reason: str, spp: int, fraction: float,
           pixels: int) -> Candidate:
    """``chosen``, an MRT plan of :func:`unmeasured_plan` for ``reason``, at
    the render's ``spp`` and grid ``fraction``; on an image of fewer than
    :data:`WIDE_PIXELS` ``pixels`` of another kind than the report's, its
    grid :data:`SMALL_IMAGE_SPREAD` times denser at as many times fewer spp.

    Examples
    --------
    >>> spread(HOME, TEXTURED_REASON, 64, 0.1, 256 * 256).label
    'idpass+oidn @ 32 spp, grid of 20 % of the pixels'
    >>> spread(HOME, HOME_REASON, 64, 0.1, 256 * 256).label
    'idpass+oidn @ 64 spp'
    """
    if pixels >= WIDE_PIXELS or reason == HOME_REASON:
        return replace(chosen, spp=spp)
    return replace(chosen, spp=max(1, math.ceil(spp / SMALL_IMAGE_SPREAD)),
                   fraction=min(1.0, SMALL_IMAGE_SPREAD * fraction))


def edge_tested(scene, tracer, params: MRTParams, width: int, height: int,
                 notes: list) -> tuple[Traced, bool]:
    """(the pixels traced, whether more than :data:`WIDE_EDGE_SHARE` of them
    lie at an edge between ids: too many for :data:`EDGE_TESTED`'s plans).

    Each pixel's ids are traced first, without the albedo (one ray a pixel
    and its lights' shadow rays: a tenth of the id pass's cost), and the id
    pass only where few enough pixels lie at an edge between them.
    """
    xy = every_pixel(width, height)
    ids_alone = tracer(xy, stream=SeedStream.ID_PASS, radiance=False, albedo=False,
                       replay=True)
    if _too_many_edges(ids_alone.ids(params.rule_for("idpass")), width, height, notes):
        return Traced(shapes=ids_alone.shape_index), True
    return Traced(trace_id_pass(tracer, width, height), ids_alone.shape_index), False


def _too_many_edges(ids: np.ndarray, width: int, height: int, notes: list) -> bool:
    """Whether more than :data:`WIDE_EDGE_SHARE` (:data:`SMALL_EDGE_SHARE` on
    an image of fewer than :data:`WIDE_PIXELS`) of the pixels lie at an edge
    between ``ids`` (the pixels'; a note says so where they do)."""
    share = edge_share(ids.reshape(height, width))
    most = WIDE_EDGE_SHARE if width * height >= WIDE_PIXELS else SMALL_EDGE_SHARE
    if share > most:
        notes.append(f"{share:.1%} of the pixels at an edge between ids: "
                     f"too many for the MRT's grid")
    return share > most


def find_surfaces(scene, tracer, width: int, height: int,
              shape_index: np.ndarray | None = None) -> tuple | None:
    """(each pixel's shape index, :func:`textured_diffuse_shapes`) where the
    scene has a textured diffuse surface, else None: the shape of every
    pixel's centre ray (``shape_index`` where given, else
    :func:`~.trace.trace_shapes`), for the passes to find the textured pixels."""
    textured = textured_diffuse_shapes(scene)
    if not textured.any():
        return None
    if shape_index is not None:
        return shape_index, textured
    return trace_shapes(scene, tracer.sensor, every_pixel(width, height), replay=True), textured


class Traced(NamedTuple):
    """What planning traced of every pixel: the id pass (:func:`trace_id_pass`)
    and each pixel's shape (the centre ray's, from the ids :func:`edge_tested`
    traced), None where not."""

    id_pass: SparseTrace | None = None
    shapes: np.ndarray | None = None

    def shape_index(self) -> np.ndarray | None:
        """Each pixel's shape index, where either trace gives it, else None."""
        if self.shapes is not None:
            return self.shapes
        return None if self.id_pass is None else self.id_pass.shape_index


def trace_id_pass(tracer, width: int, height: int) -> SparseTrace:
    """The image's id pass, as mode ``idpass`` traces it (and then reuses)."""
    return tracer(every_pixel(width, height), stream=SeedStream.ID_PASS, radiance=False,
                  replay=True)

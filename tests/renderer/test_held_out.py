"""``auto``'s held-out check of an MRT image, against images of known error."""

import mitsuba as mi
import numpy as np
import pytest

import mitsuba_mrt
from mitsuba_mrt.renderer.api import GridTracer
from mitsuba_mrt.recon.metrics import relative_error
from mitsuba_mrt.recon.sampling import every_pixel
from mitsuba_mrt.renderer.held_out import check_image, held_out_pixels, lanes_noise, noise_lanes
from mitsuba_mrt.renderer.pilot import effective_area
from mitsuba_mrt.types import SeedStream

from helpers import ball_scene_xml


@pytest.mark.parametrize("sampler", ["independent", "stratified"])
def test_the_check_tells_a_full_render_from_a_worse_and_a_better_image(variant, sampler):
    scene = mi.load_string(ball_scene_xml(96, spp=16, sampler=sampler, max_depth=3))
    sensor = scene.sensors()[0]
    tracer = GridTracer(scene, sensor, scene.integrator(), 16, 0)
    area = effective_area(sensor.film().rfilter())
    none = np.zeros((96, 96), bool)  # every pixel the image's own guess
    truth = mitsuba_mrt.render_reference(scene, spp=1024)[0]
    full = mitsuba_mrt.render_reference(scene, seed=7)[0]
    worse = mitsuba_mrt.render_reference(scene, spp=4, seed=7)[0]
    at = {name: check_image(image, none, tracer, area)
          for name, image in (("truth", truth), ("full", full), ("worse", worse))}
    for held in at.values():
        assert held.pixels == 1024 and held.full_error > 0
    # a full render's error is its noise: about what the check expects of one
    assert 0.6 < at["full"].error / at["full"].full_error < 1.6
    assert at["worse"].error > 1.5 * at["full"].error  # twice the noise
    assert at["truth"].error < 0.5 * at["full"].error


def test_the_held_out_pixels_are_untraced_and_spread():
    traced = np.zeros((64, 64), bool)
    traced[::3, ::3] = True
    index = held_out_pixels(traced, share=1 / 16, minimum=10)
    assert len(index) == 256 and len(np.unique(index)) == 256
    assert not traced.ravel()[index].any()
    rows = index // 64
    assert rows.min() < 4 and rows.max() > 59
    assert len(held_out_pixels(np.ones((8, 8), bool))) == 0
    assert len(held_out_pixels(np.zeros((8, 8), bool))) == 64


def test_an_image_traced_everywhere_needs_no_check(variant):
    scene = mi.load_string(ball_scene_xml(16, spp=4))
    tracer = GridTracer(scene, scene.sensors()[0], scene.integrator(), 4, 0)
    held = check_image(np.zeros((16, 16, 3)), np.ones((16, 16), bool), tracer, 1.0)
    assert (held.error, held.full_error, held.pixels) == (0.0, 0.0, 0)


@pytest.mark.parametrize("sampler,spp,lane_spp", [
    ("independent", 16, 8), ("independent", 1, 1), ("independent", 64, 8),
    ("stratified", 16, 8)])
def test_lanes_noise_is_a_full_renders_noise(variant, sampler, spp, lane_spp):
    # what a full render at the scene's spp differs from the truth by, pixel for
    # pixel, as a display shows them, from lanes of ``lane_spp`` (1 spp: the
    # halves' 2 scaled to 1; at 64 spp four lanes a half, as the passes trace it)
    scene = mi.load_string(ball_scene_xml(64, spp=spp, sampler=sampler, max_depth=3))
    tracer = GridTracer(scene, scene.sensors()[0], scene.integrator(), lane_spp, 0)
    lanes, k = noise_lanes(every_pixel(64, 64), lane_spp, spp)
    assert k == (4 if spp == 64 else 1)
    noise = lanes_noise(tracer(lanes, stream=SeedStream.CHECK, aovs=False).radiance, k,
                        lane_spp, spp)
    assert noise.shape == (64 * 64, 3) and (noise >= 0).all()

    def shown(image):
        return np.clip(image.reshape(-1, 3), 0.0, 1.0)
    truth = shown(mitsuba_mrt.render_reference(scene, spp=1024, seed=99)[0])
    squared = np.mean([(shown(mitsuba_mrt.render_reference(scene, seed=s)[0]) - truth) ** 2
                       for s in range(4)], axis=0)
    assert 0.8 < relative_error(noise, truth) / relative_error(squared, truth) < 1.25

"""Edge pixels that mix two regions, unmixed by their albedo (recon.mixed)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mitsuba_mrt.recon.compose import safe_albedo
from mitsuba_mrt.recon.mixed import unmix_edges


def _edge_field(share, a1=(0.8, 0.7, 0.6), a2=(0.2, 0.3, 0.1), e1=1.0, e2=3.0, size=8):
    """Id 1 left of column 4, id 2 from it; column 3 is an edge pixel whose
    footprint is ``share`` on id 1."""
    ids = np.where(np.arange(size)[None, :] < 4, 1, 2) * np.ones((size, 1), dtype=np.int64)
    left = (ids == 1)[..., None]
    albedo = np.where(left, a1, a2).astype(np.float64)
    albedo[:, 3] = share * np.asarray(a1) + (1 - share) * np.asarray(a2)
    irradiance = np.where(left, e1, e2) * np.ones(3)
    truth = np.where(left, np.asarray(a1) * e1, np.asarray(a2) * e2)
    truth[:, 3] = share * np.asarray(a1) * e1 + (1 - share) * np.asarray(a2) * e2
    return ids, albedo, irradiance, truth


@pytest.mark.parametrize("share", [0.1, 0.5, 0.9])
def test_a_mixed_edge_pixel_gets_both_regions_light(share):
    ids, albedo, irradiance, truth = _edge_field(share)
    image, unmixed = unmix_edges(irradiance, albedo, ids, np.zeros(ids.shape, bool))
    assert unmixed[:, 3].all() and unmixed.sum() == ids.shape[0]
    np.testing.assert_allclose(image, truth, rtol=1e-12)
    # what interpolation within ids alone gives it: its own region's irradiance
    assert np.abs(irradiance * albedo - truth)[:, 3].min() > 0.01


def test_pixels_that_are_not_two_plain_colours_are_left_alone():
    keep = np.zeros((8, 8), bool)

    def untouched(ids, albedo, irradiance, keep=keep):
        image, unmixed = unmix_edges(irradiance, albedo, ids, keep)
        assert not unmixed.any()
        np.testing.assert_array_equal(image, irradiance * safe_albedo(albedo))

    ids, albedo, irradiance, _ = _edge_field(0.5)
    untouched(ids, albedo, irradiance, keep=np.ones((8, 8), bool))  # traced
    textured = albedo.copy()
    textured[:, :3] *= np.array([1.0, 0.6])[np.arange(3) % 2][:, None]  # stripes
    untouched(ids, textured, irradiance)
    untouched(*_edge_field(0.5, a2=(0.8, 0.7, 0.6))[:3])  # one colour: nothing to read
    untouched(*_edge_field(0.5, a2=(0.005, 0.3, 0.1))[:3])  # a black channel
    untouched(*_edge_field(0.99)[:3])  # its own albedo, near enough
    off = albedo.copy()
    off[:, 3] = (0.2, 0.9, 0.9)  # not between the two colours
    untouched(ids, off, irradiance)
    corner = ids.copy()
    corner[:2, 2] = 3  # a third region next to the edge
    untouched(corner[:3], albedo[:3], irradiance[:3], keep=keep[:3])


@settings(max_examples=60, deadline=None, derandomize=True)
@given(share=st.floats(0, 1), a1=st.lists(st.floats(0, 1), min_size=3, max_size=3),
       a2=st.lists(st.floats(0, 1), min_size=3, max_size=3),
       e1=st.floats(0, 1e30), e2=st.floats(0, 1e30))
def test_an_unmixed_pixel_lies_between_its_two_regions(share, a1, a2, e1, e2):
    ids, albedo, irradiance, _ = _edge_field(share, a1, a2, e1, e2)
    image, unmixed = unmix_edges(irradiance, albedo, ids, np.zeros(ids.shape, bool))
    assert np.isfinite(image).all()
    assert not unmixed[:, [0, 1, 2, 5, 6, 7]].any()  # only pixels on the edge
    own = (np.asarray(a1) * e1)
    other = (np.asarray(a2) * e2)
    lo, hi = np.minimum(own, other), np.maximum(own, other)
    mixed = image[unmixed]
    assert ((mixed >= lo * (1 - 1e-12)) & (mixed <= hi * (1 + 1e-12))).all()

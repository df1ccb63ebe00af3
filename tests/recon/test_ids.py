import numpy as np
import pytest

from mitsuba_mrt import MRTError
from mitsuba_mrt.recon.ids import blocked_count, encode_ids, id_to_paper_float


def test_paper_rule_is_shape_plus_half_per_blocked_light():
    shape = np.array([0, 1, 1, 3])
    visible = np.array([0, 0b111, 0b101, 0b000])
    ids = encode_ids(shape, visible, 3, "paper")
    assert list(id_to_paper_float(ids)) == [0.0, 1.0, 1.5, 4.5]


def test_paper_rule_collides_and_exact_rule_does_not():
    # shape 1 with both lights blocked vs shape 2 with both visible
    shape, visible = np.array([1, 2]), np.array([0b00, 0b11])
    paper = encode_ids(shape, visible, 2, "paper")
    exact = encode_ids(shape, visible, 2, "exact")
    assert paper[0] == paper[1]
    assert exact[0] != exact[1]


def test_exact_rule_separates_which_light_is_blocked():
    ids = encode_ids(np.array([1, 1]), np.array([0b01, 0b10]), 2, "exact")
    assert ids[0] != ids[1]
    assert encode_ids(np.array([1, 1]), np.array([0b01, 0b10]), 2, "paper").tolist() == [3, 3]


def test_background_is_zero_whatever_the_mask():
    assert encode_ids(np.array([0]), np.array([0b1]), 1, "exact")[0] == 0
    assert encode_ids(np.array([0]), np.array([0]), 4, "paper")[0] == 0


def test_blocked_count():
    assert blocked_count(np.array([0b1011]), 4).tolist() == [1]


def test_bad_rule():
    with pytest.raises(MRTError, match="id rule"):
        encode_ids(np.array([1]), np.array([0]), 1, "fancy")

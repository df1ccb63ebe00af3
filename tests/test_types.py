"""MRTParams: the parameters validated once, up front, with exact messages."""

import json

import numpy as np
import pytest

from mitsuba_mrt import MRTError, MRTParams


@pytest.mark.parametrize("name", ["sample_fraction", "filter_sigma", "filter_cutoff",
                                  "max_inpoints", "num_cappoints", "noise_smoothing"])
def test_a_parameter_that_is_no_number_is_a_one_line_error(name):
    # (a string's comparison raised TypeError; sample_fraction="0.1" was kept as a string)
    with pytest.raises(MRTError, match=f"^{name} must be a number, got '1'$"):
        MRTParams(**{name: "1"})


def test_numpy_scalars_are_kept_as_python_numbers():
    params = MRTParams(sample_fraction=np.float32(0.25), max_inpoints=np.int64(50),
                       time_limit=np.float32(0.5))
    assert type(params.sample_fraction) is float and params.sample_fraction == 0.25
    assert type(params.max_inpoints) is int and type(params.time_limit) is float
    json.dumps(params.as_dict())


def test_an_unknown_parameter_is_named():
    with pytest.raises(MRTError, match="^unknown MRT parameter 'sampel_fraction'; the parameters "
                                      "are sample_fraction, "):
        MRTParams().with_(sampel_fraction=0.2)

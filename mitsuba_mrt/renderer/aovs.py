"""The id AOV images an MRT render adds to R, G, B (numpy only)."""

from __future__ import annotations

import numpy as np

from ..recon.compose import region_values
from ..recon.ids import id_to_paper_float

#: The AOV channels, in the order they follow R, G, B.
AOV_NAMES = ("id", "shape_index", "visible_lights", "traced")


def aov_images(result) -> dict[str, np.ndarray]:
    """Full-resolution id AOVs of an MRTResult, as float32-exact arrays.

    ``id`` is the report's float id under the paper rule, and the rank of
    the region's id among the image's ids under the exact rule.
    """
    trace, ids = result.trace, result.ids
    sample_ids = trace.ids(result.params.rule_for(result.mode))
    if result.params.rule_for(result.mode) == "paper":
        id_image = id_to_paper_float(ids)
    else:
        id_image = np.searchsorted(np.unique(ids), ids).astype(np.float64)
    return {
        "id": id_image,
        "shape_index": region_values(ids, sample_ids, trace.shape_index, "first", 0),
        "visible_lights": region_values(ids, sample_ids, trace.visible_lights, "first", 0),
        "traced": result.traced_mask.astype(np.float64),
    }

"""Shared fixtures: the session's Mitsuba variant, the ground truth of the ids.

Plain helpers (paths, the small scene) are in helpers.py, a module.
"""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def variant():
    """The variant that ``auto`` picked here (LLVM if usable); see ../conftest.py."""
    import mitsuba as mi

    return mi.variant()


@pytest.fixture(scope="session")
def true_ids(variant):
    """``true_ids(scene, rule="exact")``: every pixel's id, traced (sample fraction 1),
    the ground truth of the id stages."""
    import mitsuba_mrt

    def ids(scene, rule: str = "exact"):
        full = mitsuba_mrt.render(scene, mode="paper", sample_fraction=1.0)
        return full.trace.ids(rule).reshape(full.ids.shape)

    return ids


@pytest.fixture(autouse=True)
def no_kept_plans(monkeypatch):
    """Every test starts with no plan kept by another test's renders: a default
    ``auto`` render takes the plan an earlier one of its scene kept."""
    from mitsuba_mrt.renderer import kept_plans

    monkeypatch.setattr(kept_plans, "_plans", {})

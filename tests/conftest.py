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


@pytest.fixture(autouse=True)
def no_kept_times(monkeypatch):
    """Every test starts with no time kept by another test's time-limited
    renders (``auto_limit``'s tables: first rounds, OIDN's last calls, the
    passes' launches, the grid probe, previews): a time limit plans from
    them, so that a test's plan depended on which tests ran before it."""
    from mitsuba_mrt.renderer import auto_limit

    for name in ("_first_round_s", "_final_denoise_s", "_launch_costs", "_probe_recording_s",
                 "_probe_execute", "_preview_after_s"):
        monkeypatch.setattr(auto_limit, name, {})
    monkeypatch.setattr(auto_limit, "_preview_rate", [])

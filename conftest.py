"""Root pytest hook: choose and activate a Mitsuba variant before collection.

Doctests of the Mitsuba-facing modules need a variant to import, so the
whole session runs on one variant: the one named by the environment variable
``MITSUBA_MRT_TEST_VARIANT`` (e.g. ``cuda_ad_rgb`` on a GPU machine), else
the one ``auto`` picks (LLVM if usable).
"""

import os

import pytest

import mitsuba_mrt


def pytest_configure(config):
    try:
        mitsuba_mrt.activate(os.environ.get("MITSUBA_MRT_TEST_VARIANT", "auto"))
    except mitsuba_mrt.MRTError as exc:
        raise pytest.UsageError(f"MITSUBA_MRT_TEST_VARIANT: {exc}") from None

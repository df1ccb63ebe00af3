"""Root pytest hook: choose and activate a Mitsuba variant before collection.

Doctests of the Mitsuba-facing modules need a variant to import, so the
whole session runs on one variant: the one named by the environment variable
``MITSUBA_MRT_TEST_VARIANT`` (e.g. ``cuda_ad_rgb`` on a GPU machine), else
the one ``auto`` picks (LLVM if usable).
"""

import os

import pytest

import mitsuba_mrt

# The suite plans from what its own process measures: never from, nor into,
# what the user's earlier renders remembered (mitsuba_mrt.runtime.memory);
# the CLI's subprocesses inherit it.  Tests of the memory give it a file.
os.environ["MITSUBA_MRT_MEMORY"] = "off"


_variant: list[str] = []  # the session's variant, set by pytest_configure


def pytest_configure(config):
    try:
        _variant[:] = [mitsuba_mrt.activate(os.environ.get("MITSUBA_MRT_TEST_VARIANT", "auto"))]
    except mitsuba_mrt.MRTError as exc:
        raise pytest.UsageError(f"MITSUBA_MRT_TEST_VARIANT: {exc}") from None


@pytest.fixture(autouse=True)
def _keep_the_session_variant():
    """Give the next test the session's variant back: a test that runs the
    CLI or a job in-process activates their own choice (``auto``), and the
    tests after it would run on that one."""
    yield
    import mitsuba as mi

    if _variant and mi.variant() != _variant[0]:
        mitsuba_mrt.activate(_variant[0])

"""What Dr.Jit spent on a block's kernels, and the flags a render traces under."""

import pytest


def test_a_render_s_flags_drop_the_kernel_history_they_gathered(variant):
    import drjit as dr
    import mitsuba as mi

    from mitsuba_mrt.runtime.jit import recording_flags

    if not mi.variant().startswith(("llvm", "cuda")):
        pytest.skip("kernels are a JIT variant's")
    with recording_flags():
        dr.eval(dr.arange(mi.Float, 64) * 2.0 + 1.0)
    assert not dr.flag(dr.JitFlag.KernelHistory)  # (as it was)
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        assert dr.kernel_history() == []

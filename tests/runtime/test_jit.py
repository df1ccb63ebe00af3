"""What Dr.Jit spent on a block's kernels (a trace's own apart), and a render's flags."""

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


def test_the_widest_kernels_are_those_over_the_most_lanes_that_compute():
    import drjit as dr

    from mitsuba_mrt.runtime.jit import DATA_OPS, _widest_seconds

    jit = dr.KernelType.JIT
    history = [
        {"type": jit, "size": 4096, "operation_count": 5000, "execution_time": 7.0},
        {"type": jit, "size": 4096, "operation_count": 900, "execution_time": 2.0},
        {"type": jit, "size": 4096, "operation_count": DATA_OPS, "execution_time": 0.5},
        {"type": jit, "size": 1024, "operation_count": 800, "execution_time": 0.25},
        {"type": dr.KernelType.Memset, "size": 1 << 20, "execution_time": 0.125},
    ]
    assert _widest_seconds(history) == pytest.approx(9e-3)  # (milliseconds in, seconds out)
    assert _widest_seconds(history[2:3]) == 0.0  # data movement alone


def test_a_trace_s_own_kernels_are_a_part_of_what_its_block_ran(variant):
    import drjit as dr
    import mitsuba as mi

    from mitsuba_mrt.runtime.jit import kernel_seconds

    if not mi.variant().startswith(("llvm", "cuda")):
        pytest.skip("kernels are a JIT variant's")
    with kernel_seconds() as spent:
        x = dr.arange(mi.Float, 1 << 16)
        for _ in range(40):  # a kernel of many operations over every lane
            x = dr.sin(x) * 1.0001 + 0.5
        dr.eval(dr.block_sum(x, 64))  # ... and one over fewer lanes
    assert 0.0 < spent.widest <= spent.execute

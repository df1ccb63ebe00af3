import pytest

from mitsuba_mrt.app.job import RunSummary, summary_line
from mitsuba_mrt.types import Skips, Timings, TracedCounts


def summary(timings: Timings) -> RunSummary:
    return RunSummary(scene="scenes_xml/x.xml", variant="llvm_ad_rgb", width=10, height=10,
                      spp=4, mode="auto", mode_used="refine", why="asked for",
                      sample_fraction=0.1, traced=TracedCounts(grid=16, more=4),
                      timings=timings, skipped=Skips(), auto=None, reference_time_s=None,
                      relative_time=None, error=None, psnr_db=None, params={}, defines={},
                      seed=0, stats={}, environment={})


def test_summary_line_names_every_part_of_the_time_that_was_spent():
    line = summary_line(summary(Timings(trace=0.5, trace_more=0.1, check=0.2, denoise=0.04,
                                        interpolate=0.1).close(1.0)))
    assert "1.000 s = trace 0.500 + more 0.100 + pilot 0.200 + denoise 0.040" in line
    assert line.endswith("+ other 0.060 [llvm_ad_rgb]")


def test_summary_line_counts_the_kernels_compiled_only_when_there_were_some():
    from mitsuba_mrt.types import KernelCounts

    timings = Timings(trace=0.5, compile=KernelCounts(compiled=3, from_disk=2)).close(1.0)
    assert "+ other 0.500 (3 kernels compiled) [" in summary_line(summary(timings))
    timings.compile = KernelCounts(compiled=1, from_disk=2)
    assert "+ other 0.500 (1 kernel compiled) [" in summary_line(summary(timings))
    timings.compile = KernelCounts(compiled=0, from_disk=2)
    assert "compiled" not in summary_line(summary(timings))


def test_summary_line_leaves_out_the_parts_a_run_did_not_have():
    line = summary_line(summary(Timings(trace=0.5, interpolate=0.1).close(1.0)))
    assert "pilot" not in line and "denoise" not in line and "full render" not in line
    assert "traced 16 grid + 4 at edges = 20.0% of the pixels" in line


def test_the_progress_bar_is_silent_off_a_terminal(capsys):
    from mitsuba_mrt.app.job import progress_bar

    with progress_bar(True) as tell:  # pytest's stderr is no terminal
        tell("passes (2 spp)", 0.5)
    assert capsys.readouterr().err == ""


def test_a_jobs_overrides_go_on_top_of_the_scenes_parameters():
    from mitsuba_mrt import MRTError, MRTParams
    from mitsuba_mrt.app.job import RenderJob

    job = RenderJob(scene="x.xml", param_overrides={"sample_fraction": 0.2})
    scene_params = MRTParams(filter_sigma=2.0)
    assert job.params_for(scene_params) == MRTParams(filter_sigma=2.0, sample_fraction=0.2)
    assert job.params_for(None) == MRTParams(sample_fraction=0.2)
    with pytest.raises(MRTError, match="sample_fraction"):
        RenderJob(scene="x.xml", param_overrides={"sample_fraction": 2.0}).params_for(None)


def test_parameters_without_a_change_are_the_same_object():
    from mitsuba_mrt import MRTParams

    params = MRTParams(filter_sigma=2.0)
    assert params.with_() is params
    assert params.with_(time_limit=None) is params
    assert params.with_(time_limit=1.0) == MRTParams(filter_sigma=2.0, time_limit=1.0)
    assert params.with_(time_limit=1.0) is not params


def test_why_says_an_mrt_images_check_found_no_error_it_could_resolve():
    from types import SimpleNamespace

    from mitsuba_mrt.app.job import _why
    from mitsuba_mrt.modes.plan import Candidate, Plan

    def why(error):
        choice = Candidate("idpass+oidn", "mrt", 64, mode="idpass", denoise=True, error=error)
        return _why(SimpleNamespace(auto=Plan(choice, "the reason", target_error=0.0646)))

    assert why(0.0).endswith("(estimated error below what its check resolves, "
                             "a full render's 0.0646)")
    assert why(0.0123).endswith("(estimated error 0.0123, a full render's 0.0646)")

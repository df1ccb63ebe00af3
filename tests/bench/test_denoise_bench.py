"""``bench denoise``: the MRT against OIDN end to end (quick), and its tables' arithmetic."""

import math

import pytest

from mitsuba_mrt.app.cli import main
from mitsuba_mrt.bench import analysis, experiments, measure_denoise, memory, records

from helpers import SCENES


def test_the_experiment_covers_fig1_and_the_gallery():
    exp = experiments.build_experiment("denoise")
    assert exp.kind == "denoise" and exp.ladder == (1, 2, 4, 8, 16, 32, 64)
    fig1, *gallery = exp.points
    assert fig1.defines == {"res": 400, "integrator": "path", "spp": 64, "jitter": "true"}
    assert [p.group for p in gallery] == list(experiments.GALLERY_SCENES)
    assert all(p.defines == {"res": 128, "spp": 64} for p in gallery)
    assert [s.params["denoise"] for s in fig1.settings] == ["none", "oidn", "oidn"] + [
        "none", "oidn"] * 2
    assert fig1.settings[2].params["denoise_quality"] == "balanced"
    assert [s.params["sample_fraction"] for s in fig1.settings] == [0.1] * 3 + [0.05] * 2 + [
        0.2] * 2
    # the balanced setting is measured with fast and idpass, the other fractions with fast
    pairs = experiments.setting_pairs(fig1, list(experiments.DENOISE_METHODS))
    assert [(s, m) for s, m in pairs if s == 2] == [(2, "mrt-fast"), (2, "mrt-idpass")]
    assert [(s, m) for s, m in pairs if s > 2] == [(s, "mrt-fast") for s in range(3, 7)]
    assert experiments.denoised_name("mrt-fast", fig1.settings[2].params) == (
        "mrt-fast+oidn-balanced")
    assert experiments.denoised_mode("mrt-fast+oidn-balanced") == ("mrt-fast", "+oidn-balanced")
    assert experiments.denoised_name("mrt-fast", fig1.settings[0].params) == "mrt-fast"
    # the gallery also runs the configurations closest to the full render's error
    # beyond 64 spp, under the same labels (so on the same curves); Fig. 1 does not
    assert all(not s.ladder for s in fig1.settings)
    beyond = gallery[0].settings[len(fig1.settings):]
    assert gallery[0].settings[:len(fig1.settings)] == fig1.settings
    assert [(s.label, s.methods, s.ladder) for s in beyond] == [
        ("f=0.1, denoise=oidn", ("mrt-refine", "mrt-idpass"), (128, 256)),
        ("f=0.2, denoise=oidn", ("mrt-fast",), (128, 256))]
    assert "denoise" in experiments.EXPERIMENTS


def test_quick_denoise_has_oidn_rows(tmp_path, monkeypatch):
    pytest.importorskip("mitsuba_oidn")
    argv = ["bench", "denoise", "--quick", "--res", "24", "-o", str(tmp_path),
            "--scenes", str(SCENES), "--no-progress"]
    assert main(argv) == 0
    rows = analysis.read_csv(tmp_path / "denoise.csv")
    assert tuple(rows[0]) == records.DENOISE_COLUMNS == (
        "scene", "method", "setting", "spp", "total_s", "relative_time", "error_converged",
        "psnr_converged")
    fig1 = [r for r in rows if r["scene"] == "paper_fig1.xml"]
    noise_free = [r for r in fig1 if r["setting"] == records.NOISE_FREE]
    fig1 = [r for r in fig1 if r not in noise_free]
    assert {r["method"] for r in fig1} == {"full", "oidn", "oidn-noaux", "mrt-fast",
                                           "mrt-fast+oidn", "mrt-fast+oidn-balanced"}
    balanced = [r for r in fig1 if r["method"] == "mrt-fast+oidn-balanced"]
    assert {r["setting"] for r in balanced} == {"f=0.1, denoise=oidn, quality=balanced"}
    assert sorted(int(r["spp"]) for r in balanced) == [1, 4]
    assert {r["setting"] for r in fig1 if r["method"] == "mrt-fast+oidn"} == {
        "f=0.1, denoise=oidn", "f=0.05, denoise=oidn", "f=0.2, denoise=oidn"}
    curves = analysis.denoise_curves(rows)["paper_fig1"]
    assert {"mrt-fast", "mrt-fast f=0.05", "mrt-fast+oidn f=0.2",
            "mrt-fast+oidn-balanced"} <= set(curves)
    assert all(len(curves[label]) == 2 for label in curves if label.startswith("mrt-"))
    assert [(r["method"], r["spp"]) for r in noise_free] == [("mrt-fast", "4")]
    assert math.isnan(float(noise_free[0]["total_s"]))
    assert 0 < float(noise_free[0]["error_converged"]) < float(
        next(r for r in fig1 if r["method"] == "mrt-fast" and r["spp"] == "4")["error_converged"])
    for r in fig1:
        for column in ("total_s", "relative_time", "error_converged", "psnr_converged"):
            assert math.isfinite(float(r[column])), (r["method"], column)
    full = {int(r["spp"]): r for r in fig1 if r["method"] == "full"}
    assert sorted(full) == [1, 4] and full[1]["setting"] == "sampler=stratified"
    assert float(full[4]["relative_time"]) == 1.0
    oidn = [r for r in fig1 if r["method"] == "oidn"]
    assert {r["setting"] for r in oidn} == {f"quality={q}" for q in experiments.OIDN_QUALITIES}
    for r in oidn:  # the full render's time, plus the guides and OIDN
        assert float(r["total_s"]) > float(full[int(r["spp"])]["total_s"])
        assert float(r["error_converged"]) < float(full[int(r["spp"])]["error_converged"])
    md = (tmp_path / "denoise.md").read_text()
    assert md.startswith("Command: `python -m mitsuba_mrt bench denoise --quick")
    assert "### Equal error" in md and "### Equal time" in md
    assert "paper_fig1: sampler `stratified`, spp 1, 4" in md
    assert (tmp_path / "denoise.png").read_bytes()[:4] == b"\x89PNG"
    assert (tmp_path / "cache" / "paper_fig1_24_64.npy").is_file()
    # the gallery's scene: fast+oidn at f=0.2 once more beyond the ladder's top, on
    # the same curve, timed against the same full render
    gallery = [r for r in rows if r["scene"] == "gallery/checker_border.xml"
               and r["setting"] != records.NOISE_FREE]
    assert sorted(int(r["spp"]) for r in gallery if r["method"] == "full") == [1, 4]
    beyond = [r for r in gallery if int(r["spp"]) == 8]
    assert [(r["method"], r["setting"]) for r in beyond] == [
        ("mrt-fast+oidn", "f=0.2, denoise=oidn")]
    for column in ("total_s", "relative_time", "error_converged"):
        assert math.isfinite(float(beyond[0][column]))
    curve = analysis.denoise_curves(rows)["checker_border"]["mrt-fast+oidn f=0.2"]
    assert [int(p[2]["spp"]) for p in curve] == [1, 4, 8]


@pytest.mark.parametrize("scene, defines, beyond", [
    ("paper_fig1.xml", {"integrator": "path", "jitter": "true"}, 9),  # stratified: 2 -> 4
    ("gallery/cornell.xml", {}, 8),
])
def test_the_progress_bar_ends_at_its_total(scene, defines, beyond):
    """Every tick counted up front is made, where the sampler rounds spp and where a
    setting goes beyond the ladder's top (the quick one: 8 spp)."""
    pytest.importorskip("mitsuba_oidn")
    exp = experiments.build_experiment("denoise", quick=True, res=12)
    exp.ladder = (1, 2)
    base = exp.points[1].settings
    point = experiments.Point(scene, {"res": 12, "spp": 2, **defines}, 2,
                              [base[0], base[-1]], group="x")
    methods = ["full", "mrt-fast"]
    ticks = []
    runner = measure_denoise.DenoiseRunner(exp, point, methods, 1, SCENES,
                                           memory.MemoryMeter(), {},
                                           lambda: ticks.append(1), min_seconds=0.0)
    rows, _ = runner.run()
    assert len(ticks) == measure_denoise.DenoiseRunner.ticks(exp, point, methods, 1)
    assert [r.spp for r in rows if r.method == "mrt-fast+oidn"] == [beyond]


def _rows(curves):
    """CSV-like rows of {(method, setting): [(spp, relative time, error)]}, full at 1 s."""
    out = []
    for (method, setting), points in curves.items():
        for spp, t, e in points:
            out.append({"scene": "gallery/x.xml", "method": method, "setting": setting,
                        "spp": str(spp), "total_s": str(t), "relative_time": str(t),
                        "error_converged": str(e), "psnr_converged": "30"})
    return out


def test_equal_error_is_interpolated_log_log():
    points = [(0.01, 0.04, None), (0.04, 0.01, None)]
    t, how = analysis.time_to_reach(points, 0.02)
    assert how == "" and t == pytest.approx(0.02)  # halfway in log error, log time
    assert analysis.time_to_reach(points, 0.05) == (0.01, "<=")
    t, how = analysis.time_to_reach(points, 0.001)
    assert math.isnan(t) and how == "not reached"


def test_equal_time_compares_within_each_budget():
    rows = _rows({
        ("full", "sampler=independent"): [(16, 0.25, 0.04), (64, 1.0, 0.02)],
        ("mrt-fast", "f=0.1"): [(4, 0.02, 0.05), (64, 0.12, 0.015)],
        ("oidn", "quality=fast"): [(1, 0.15, 0.03), (4, 0.3, 0.01)],
    })
    curves = analysis.denoise_curves(rows)["x"]
    verdict = analysis.equal_time_verdict(curves)
    # at 0.15 OIDN has 0.03, the MRT 0.05; from 0.12 on, 0.015 against 0.03
    assert verdict["holds"] and verdict["least_gain"] == pytest.approx(2.0)
    slow = _rows({("full", "s"): [(64, 1.0, 0.02)], ("mrt-fast", "f"): [(4, 0.2, 0.05)],
                  ("oidn", "quality=fast"): [(1, 0.1, 0.03)]})
    verdict = analysis.equal_time_verdict(analysis.denoise_curves(slow)["x"])
    assert not verdict["holds"] and math.isinf(verdict["worst"]) and verdict["at"] == 0.1
    summary = analysis.denoise_summary(rows)[0]
    assert summary["mrt"][0] == "mrt-fast" and summary["b_target"] == 0.10
    label, t, how = summary["oidn"]  # 0.03 at 0.15, 0.01 at 0.3: 0.02 in between
    assert label == "oidn fast" and 0.15 < t < 0.3 and how == ""
    lines = analysis.denoise_tables(rows)
    assert any(line.startswith("| x | mrt-fast | 64 | 0.12 | 0.015 | oidn fast, 1 spp")
               for line in lines)


def test_the_ladder_follows_the_sampler_and_guides_are_in_range(variant):
    from mitsuba_mrt.renderer.guides import render_guides, sampler_spp
    from mitsuba_mrt.renderer.scene import load_scene

    fig1 = load_scene(SCENES / "paper_fig1.xml", res=16, integrator="path", spp=4,
                      jitter="true")
    assert [sampler_spp(fig1, n) for n in (1, 2, 8, 64)] == [
        ("stratified", 1), ("stratified", 4), ("stratified", 9), ("stratified", 64)]
    gallery = load_scene(SCENES / "gallery" / "cornell.xml", res=16, spp=4)
    assert [sampler_spp(gallery, n)[1] for n in (1, 2, 8)] == [1, 2, 8]
    albedo, normal, seconds = render_guides(fig1)
    assert albedo.shape == normal.shape == (16, 16, 3) and seconds > 0
    assert albedo.min() >= 0 and albedo.max() <= 1 and albedo.max() > 0.1
    assert normal.min() >= -1 and normal.max() <= 1 and abs(normal).max() > 0.5

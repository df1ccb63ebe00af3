"""``bench rival``: the alternative's curve, the verdicts, one small scene end to end."""

from pathlib import Path

import pytest

from mitsuba_mrt.bench.rival import (PLANNED, Row, alternative_at, at_time, rel_mse, run_rival,
                                     verdicts)

ROOT = Path(__file__).resolve().parents[2]


def rows():
    out = [Row("s", f"oidn@{spp}", spp, 0.0, t, e, 0.0) for spp, t, e in
           ((1, 0.1, 0.04), (4, 0.4, 0.02), (16, 1.6, 0.01))]
    out += [Row("s", "full", 64, 1.0, 1.0, 0.03, 0.0),
            Row("s", "auto", 64, 0.0, 0.2, 0.02, 0.0, "refine+oidn @ 64 spp"),
            Row("s", PLANNED, 64, 0.0, 0.4, 0.02, 0.0, "refine+oidn @ 64 spp"),
            Row("s", "refine+oidn", 64, 0.0, 0.15, 0.018, 0.0),
            Row("s", "auto --time-limit 0.25", 64, 0.0, 0.26, 0.021, 0.0)]
    return out


def test_the_alternative_is_interpolated_on_its_curve_in_log_log():
    # halfway (in log time) between 0.1 and 0.4: the geometric mean of the errors
    assert at_time(rows(), "oidn@", 0.2) == pytest.approx((0.04 * 0.02) ** 0.5)
    assert at_time(rows(), "oidn@", 0.01) == pytest.approx(0.04)  # beyond the ends: the end


def test_the_alternative_is_the_lower_of_its_presets_curves():
    high = [Row("s", f"oidn-high@{spp}", spp, 0.0, t, e, 0.0) for spp, t, e in
            ((4, 0.5, 0.015), (16, 1.7, 0.009))]
    both = rows() + high
    assert alternative_at(both, 0.2) == pytest.approx(at_time(rows(), "oidn@", 0.2))  # before high
    assert alternative_at(both, 0.5) == pytest.approx(0.015)  # high's point, below fast's curve
    assert alternative_at(both, 3.0) == pytest.approx(0.009)  # both beyond their ends
    (v,) = verdicts(both)
    assert v["limits"][0.25][2] == 0.04  # within the limit: fast's 1 spp alone


def test_verdicts_compare_auto_with_the_alternative_and_hindsight():
    (v,) = verdicts(rows())
    assert v["auto"].method == "auto" and v["alternative"] == pytest.approx(0.02828, rel=1e-3)
    assert v["best"] == 0.018  # refine+oidn, within auto's time; auto itself not counted
    assert v["planned"].method == PLANNED and v["planned_ratio"] == pytest.approx(1.0)
    ratio, error, best_within = v["limits"][0.25]
    assert ratio == pytest.approx(0.26 / 0.25) and error == 0.021 and best_within == 0.04


def test_without_oidn_the_alternative_is_the_full_render_curve():
    plain = [Row("s", f"full@{spp}", spp, 0.0, spp / 64, e, 0.0) for spp, e in
             ((4, 0.08), (16, 0.04), (64, 0.02))]
    plain += [Row("s", "full", 64, 1.0, 1.0, 0.02, 0.0),
              Row("s", "auto", 64, 0.0, 0.25, 0.03, 0.0, "idpass @ 64 spp"),
              Row("s", "auto --time-limit 0.5", 64, 0.0, 0.45, 0.05, 0.0, "passes @ 28 spp")]
    assert alternative_at(plain, 0.25) == pytest.approx(0.04)
    assert alternative_at(plain, 0.01) == pytest.approx(0.08)  # its 1st rung stands for less
    (v,) = verdicts(plain)
    assert v["alternative"] == pytest.approx(0.04) and v["limits"][0.5][2] == 0.04


def test_rival_without_oidn_renders_the_plain_ladder_as_if_oidn_were_missing(tmp_path, variant,
                                                                           monkeypatch):
    from mitsuba_mrt.recon import denoise
    from mitsuba_mrt.renderer import api

    seen, render = [], api.render

    def spy(*args, **kwargs):
        seen.append(denoise.oidn_available())
        return render(*args, **kwargs)
    monkeypatch.setattr(api, "render", spy)
    run_rival(tmp_path, [(ROOT / "scenes_xml" / "gallery" / "cornell.xml", "cornell",
                          {"res": 32, "spp": 4})], repeats=1, quick=True,
              command="test", echo=lambda line: None, oidn=False)
    lines = (tmp_path / "rival.csv").read_text().splitlines()
    methods = {line.split(",")[1] for line in lines[1:]}
    assert {"full", "full@1", "full@4", "auto", "fast", "idpass",
            "auto --time-limit 0.5"} <= methods
    assert not any(m.startswith("oidn") or m.endswith("+oidn") for m in methods)
    assert seen and not any(seen)  # every render as without OIDN


def test_rel_mse_weighs_dark_pixels_more():
    import numpy as np

    dark, bright = np.full((1, 1, 3), 0.1), np.full((1, 1, 3), 1.0)
    assert rel_mse(dark + 0.1, dark) > rel_mse(bright + 0.1, bright)


def test_rival_writes_its_table_for_a_small_scene(tmp_path, variant, monkeypatch):
    from mitsuba_mrt.renderer import api

    limits, render = [], api.render

    def spy(*args, **kwargs):
        limits.append(kwargs.get("time_limit"))
        return render(*args, **kwargs)
    monkeypatch.setattr(api, "render", spy)
    table = run_rival(tmp_path, [(ROOT / "scenes_xml" / "gallery" / "cornell.xml", "cornell",
                                  {"res": 32, "spp": 4})], repeats=1, quick=True,
                      command="test", echo=lambda line: None)
    text = table.read_text()
    assert "| cornell |" in text and "Command: `test`" in text
    assert (tmp_path / "rival.png").stat().st_size > 0
    lines = (tmp_path / "rival.csv").read_text().splitlines()
    methods = {line.split(",")[1] for line in lines[1:]}
    # the converged renders: their own error in the table, kept for the next run
    assert "converged renders' own error" in text and "(256 spp) |" in text
    assert list((tmp_path / "cache").glob("rival_cornell_32x32_256.npz"))
    assert lines[0].split(",")[7] == "flip"
    assert {"full", "oidn@1", "oidn@4", "oidn-high@4", "auto", PLANNED, "fast", "refine+oidn",
            "auto --time-limit 0.1"} <= methods
    # each limit warmed up once, as every other method, then its one timed repeat
    timed = [limit for limit in limits if limit is not None]
    assert len(timed) == 6 and timed[0] == timed[1] < timed[2] == timed[3] < timed[4]


def test_flip_is_zero_for_the_same_image_and_grows_with_the_difference():
    pytest.importorskip("flip_evaluator")
    import numpy as np

    from mitsuba_mrt.bench.rival import flip_error

    image = np.random.default_rng(0).random((32, 32, 3))
    assert flip_error(image, image) == 0.0
    near, far = flip_error(image + 0.02, image), flip_error(image + 0.2, image)
    assert 0.0 < near < far


def test_without_flip_evaluator_flip_is_nan(monkeypatch):
    import math
    import sys

    import numpy as np

    from mitsuba_mrt.bench.rival import flip_error

    monkeypatch.setitem(sys.modules, "flip_evaluator", None)
    assert math.isnan(flip_error(np.zeros((4, 4, 3)), np.zeros((4, 4, 3))))


def test_the_noise_free_mse_is_the_error_against_what_the_reference_converges_to():
    import numpy as np

    from mitsuba_mrt.bench.rival import noise_free_mse

    rng = np.random.default_rng(1)
    truth = 0.2 + 0.6 * rng.random((200, 200, 3))
    image = truth + 0.05  # an error of its own
    sigma = 0.06  # a noisy reference, its noise larger than the error
    reference = truth + sigma * rng.standard_normal(truth.shape)
    exact = float(np.mean((image - truth) ** 2))
    assert noise_free_mse(image, reference, np.zeros(truth.shape)) > 2 * exact
    assert noise_free_mse(image, reference, np.full(truth.shape, sigma ** 2)) == pytest.approx(
        exact, rel=0.05)


def test_converged_renders_know_their_own_noise_and_are_kept(tmp_path, variant, monkeypatch):
    import numpy as np

    import mitsuba_mrt
    from mitsuba_mrt.bench import rival

    scene = mitsuba_mrt.load_scene(ROOT / "scenes_xml" / "gallery" / "cornell.xml", res=16)
    cache = tmp_path / "cache" / "truth.npz"
    truth = rival.converged_truth(scene, 256, cache)
    for kind in ("film", "box"):
        assert truth[kind].shape == truth.variances[kind].shape == (16, 16, 3)
        assert (truth.variances[kind] >= 0).all() and truth.variances[kind].max() > 0
        assert 0 < truth.own_errors[kind] < 0.5
    assert cache.is_file()

    def no_render(*args):
        raise AssertionError("rendered again")
    monkeypatch.setattr(rival, "_converged", no_render)
    again = rival.converged_truth(scene, 256, cache)
    assert np.array_equal(again["box"], truth["box"]) and again.own_errors == truth.own_errors
    # a file of another image size is not taken
    other = mitsuba_mrt.load_scene(ROOT / "scenes_xml" / "gallery" / "cornell.xml", res=8)
    with pytest.raises(AssertionError, match="rendered again"):
        rival.converged_truth(other, 256, cache)
    # what the examples read: the file bench rival keeps in its folder for the scene
    rival.truth_file(tmp_path, "cornell", scene, 256).write_bytes(cache.read_bytes())
    kept = rival.kept_truth(scene, "cornell", tmp_path, 256)
    assert np.array_equal(kept["film"], truth["film"])


def test_a_bad_truth_spp_is_one_line_and_exit_2(tmp_path):
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-m", "mitsuba_mrt", "bench", "rival", "--truth-spp",
                          "100", "-o", str(tmp_path / "out")], capture_output=True, text=True,
                         cwd=ROOT)
    assert out.returncode == 2 and not (tmp_path / "out").exists()
    assert out.stderr.strip() == "error: --truth-spp must be a multiple of 128, got 100"


def test_no_oidn_outside_rival_is_one_line_and_exit_2(tmp_path):
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-m", "mitsuba_mrt", "bench", "gallery", "--no-oidn",
                          "-o", str(tmp_path / "out")], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 2 and not (tmp_path / "out").exists()
    assert out.stderr.strip() == "error: --no-oidn is an option of bench rival"

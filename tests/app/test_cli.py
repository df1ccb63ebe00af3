"""The command line, run as a user would: in a subprocess."""

import json
import subprocess
import sys

import numpy as np
import pytest

from helpers import ROOT, SCENES


def run_cli(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", "mitsuba_mrt", *map(str, args)],
                          cwd=cwd, capture_output=True, text=True, timeout=300)


def test_render_writes_every_output(tmp_path):
    proc = run_cli("render", SCENES / "paper_fraction.xml", "-o", tmp_path, "-D", "res=48",
                   "--sample-fraction", "0.2", "--mode", "refine")
    assert proc.returncode == 0, proc.stderr
    assert len(proc.stdout.strip().splitlines()) == 1 and "error" in proc.stdout
    names = {p.name for p in tmp_path.iterdir()}
    assert names == {"paper_fraction_mrt.exr", "paper_fraction_mrt.png", "paper_fraction_ref.exr",
                     "paper_fraction_ref.png", "paper_fraction_error.png", "paper_fraction.json"}
    summary = json.loads((tmp_path / "paper_fraction.json").read_text())
    assert summary["width"] == summary["height"] == 48  # -D res=48 took effect
    assert summary["sample_fraction"] == 0.2
    timings = summary["timings"]
    assert set(timings) == {"trace", "trace_more", "check", "denoise", "edges", "interpolate",
                            "full_render", "other", "total", "compile"}
    # the parts add up to the total; beside them, the kernels the render did not have
    assert sum(v for k, v in timings.items() if k not in ("total", "compile")) == pytest.approx(
        timings["total"])
    assert set(timings["compile"]) == {"compiled", "from_disk"}
    assert summary["traced"]["grid"] > 0 and summary["traced"]["more"] > 0  # refine's edges
    for key in ("variant", "why", "reference_time_s", "error", "psnr_db", "params"):
        assert key in summary
    assert 0.0 <= summary["error"] < 0.05

    from mitsuba_mrt.imageio import read_exr

    channels = read_exr(tmp_path / "paper_fraction_mrt.exr")
    assert {"R", "G", "B", "id", "shape_index", "visible_lights", "traced"} <= set(channels)
    assert channels["traced"].sum() == sum(summary["traced"].values())
    assert channels["R"].shape == (48, 48)


def test_auto_in_full_renders_once_and_says_so(tmp_path):
    proc = run_cli("render", SCENES / "paper_fraction.xml", "-o", tmp_path, "-D", "res=32")
    assert proc.returncode == 0, proc.stderr
    assert "mode full (auto: full @ 1 spp, too few samples" in proc.stdout and "PSNR" not in proc.stdout
    summary = json.loads((tmp_path / "paper_fraction.json").read_text())
    assert summary["mode_used"] == "full" and summary["error"] is None
    assert summary["reference_time_s"] == summary["timings"]["full_render"] > 0
    assert not (tmp_path / "paper_fraction_ref.exr").exists()


def test_json_flag_and_no_reference(tmp_path):
    proc = run_cli("render", SCENES / "paper_objects_2.xml", "-o", tmp_path, "-D", "res=32",
                   "--no-reference", "--json", "--id-rule", "exact", "--mode", "bicubic")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["error"] is None and summary["params"]["id_rule"] == "exact"
    assert summary["mode"] == "bicubic"
    assert not (tmp_path / "paper_objects_2_ref.exr").exists()


BAD = [
    (["render", "missing.xml"], "scene file not found"),
    # a folder was "not found", which it is not
    (["render", SCENES], f"a folder, not a scene file: {SCENES}"),
    (["render", SCENES / "paper_fraction.xml", "--sample-fraction", "0"], "sample_fraction"),
    (["render", SCENES / "paper_fraction.xml", "--sample-fraction", "1.5"], "sample_fraction"),
    (["render", SCENES / "paper_fraction.xml", "--filter-sigma", "-1"], "filter_sigma"),
    # (its taps alone would take 60 GiB: a MemoryError, exit status 1, before the bound)
    (["render", SCENES / "paper_fraction.xml", "--filter-sigma", "1e9"],
     "filter_sigma must be in [0, 100], got 1000000000.0"),
    (["render", SCENES / "paper_fraction.xml", "--variant", "llvm_rgb"], "invalid choice"),
    (["render", SCENES / "paper_fraction.xml", "-D", "res"], "name=value"),
    (["render", SCENES / "paper_fraction.xml", "-D", "res=abc"], "could not parse integer"),
    (["render", SCENES / "paper_fraction.xml", "--spp", "0"], "spp must be >= 1"),
    # a sampler's seed is a 32-bit unsigned integer (Mitsuba's own error is a TypeError)
    (["render", SCENES / "paper_fraction.xml", "--seed", "-1"],
     "seed must be an integer in [0, 2^32), got -1"),
    (["render", SCENES / "paper_fraction.xml", "--seed", str(1 << 32)], "seed must be"),
    # the scene's own sampler at 0 samples: a kernel would divide by it (SIGFPE)
    (["render", SCENES / "gallery" / "cornell.xml", "-D", "spp=0"],
     "spp=0 sets the scene's sample_count, which must be >= 1"),
    # a stratified sampler rounds 0 up to 1 sample: refused as asked, not rendered at 1
    (["render", SCENES / "paper_fig1.xml", "-D", "spp=-3"],
     "spp=-3 sets the scene's sample_count, which must be >= 1"),
    (["render", SCENES / "paper_fraction.xml", "--mode", "magic"], "unknown mode"),
    (["render", SCENES / "gallery" / "two_sensors.xml", "--sensor", "2", "-D", "res=16"],
     "sensor index 2 out of range: the scene has 2"),
    (["render", SCENES / "paper_fraction.xml", "--sensor", "-1"],
     "sensor index -1 out of range: the scene has 1"),
    (["batch", SCENES / "paper_fraction.xml", "--sensor", "-1"],
     "sensor must be an index >= 0, got -1"),
    # Mitsuba's list of unused parameters is on the lines after its first
    (["render", SCENES / "paper_fraction.xml", "-D", "foo=1", "-D", "bar=2"],
     "Found unused parameters: $foo=1, $bar=2"),
    # an empty film: Dr.Jit's "see above" error, unless refused when loading
    (["render", SCENES / "paper_fraction.xml", "-D", "res=0"], "the film is 0 x 0 pixels"),
    # more memory than there is: refused before any work, with an estimate
    (["render", SCENES / "paper_fraction.xml", "-D", "res=100000"],
     "100000 x 100000 render needs about 2.5 TB of memory (250 bytes per pixel)"),
    (["bench", "rival", "--quick", "--repeats", "0"], "--repeats must be an integer >= 1, got 0"),
    (["bench", "rival", "--quick", "--repeats", "-2"], "--repeats must be an integer >= 1, got -2"),
    # 0 was taken as no --res at all, and the bench ran at 256 px
    (["bench", "rival", "--quick", "--res", "0"], "--res must be >= 8, got 0"),
]


def test_each_sensor_of_a_scene_renders_under_its_own_name(tmp_path):
    # the command line rendered the first sensor only: a scene's second camera
    # was out of reach without Python
    shared = ["-D", "res=24", "-D", "spp=4", "--mode", "fast", "-o", tmp_path, "--json"]
    runs = [run_cli("render", SCENES / "gallery" / "two_sensors.xml", *shared, *extra)
            for extra in ([], ["--sensor", "1"])]
    assert [proc.returncode for proc in runs] == [0, 0], runs[1].stderr
    first, second = (json.loads(proc.stdout) for proc in runs)
    assert (first["sensor"], second["sensor"]) == (0, 1)
    assert "two_sensors_sensor1_mrt.exr" in second["outputs"]
    assert (tmp_path / "two_sensors_mrt.exr").exists()  # (not overwritten)
    assert second["error"] < 0.05  # against the second sensor's own full render
    assert first["error"] != second["error"]


@pytest.mark.parametrize("args,message", BAD)
def test_bad_input_is_one_line_and_nonzero(tmp_path, args, message):
    proc = run_cli(*args, "-o", tmp_path / "out")
    assert proc.returncode != 0
    assert message in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_malformed_xml(tmp_path):
    bad = tmp_path / "bad.xml"
    bad.write_text('<scene version="3.0.0"><shape type="sphere"></scene>')
    proc = run_cli("render", bad, "-o", tmp_path / "out")
    assert proc.returncode == 2 and "malformed XML" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_a_scene_mitsuba_cannot_render_is_bad_input(tmp_path):
    # Found trying a user's scene: a bump map over a texture without gradients
    # makes Mitsuba raise "not implemented" in the trace; it exited 1 as if the
    # package had failed.
    bad = tmp_path / "bump.xml"
    bad.write_text("""<scene version="3.0.0">
      <integrator type="path"/>
      <sensor type="perspective">
        <film type="hdrfilm">
          <integer name="width" value="24"/><integer name="height" value="24"/>
        </film>
        <sampler type="independent"><integer name="sample_count" value="2"/></sampler>
      </sensor>
      <shape type="sphere"><bsdf type="bumpmap">
        <texture type="checkerboard" name="arbitrary"/><bsdf type="diffuse"/>
      </bsdf></shape>
      <emitter type="constant"/>
    </scene>""")
    proc = run_cli("render", bad, "-o", tmp_path / "out", "--mode", "fast")
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.startswith("error: Mitsuba cannot render this scene: ")
    assert "not implemented" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_a_mode_with_a_particle_tracer_is_one_line_exit_2_and_no_output(tmp_path):
    # (a particle tracer traces from the lights: no chosen pixels; auto renders it in full)
    proc = run_cli("render", SCENES / "paper_fraction.xml", "-o", tmp_path / "out", "-D", "res=24",
                   "-D", "integrator=ptracer", "--mode", "fast")
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip() == ("error: mode fast traces chosen pixels, which a "
                                   "ParticleTracerIntegrator cannot (mode auto renders it in full)")
    assert not (tmp_path / "out").exists()


def test_inf_radiance_leaves_no_output(tmp_path):
    text = (SCENES / "paper_fraction.xml").read_text()
    bad = tmp_path / "inf.xml"
    import re

    bad.write_text(re.sub(r'name="intensity" value="[^"]*"', 'name="intensity" value="inf"', text))
    proc = run_cli("render", bad, "-o", tmp_path / "out", "-D", "res=24")
    assert proc.returncode == 2 and "NaN or Inf radiance" in proc.stderr
    assert not (tmp_path / "out").exists()


def test_failed_write_leaves_no_partial_file(tmp_path):
    from mitsuba_mrt import MRTError
    from mitsuba_mrt.imageio import write_exr

    target = tmp_path / "x.exr"
    with pytest.raises(MRTError):
        write_exr(target, {"R": np.zeros((2, 2)), "bad": np.zeros(3)})
    assert list(tmp_path.iterdir()) == []


def test_output_folder_under_a_file_is_refused_before_any_work(tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    proc = run_cli("render", SCENES / "paper_fraction.xml", "-o", blocker / "out", "-D", "res=16")
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip() == f"error: cannot write into {blocker / 'out'}: {blocker} is not a folder"


def test_a_full_disk_is_one_line_exit_2_and_leaves_no_file(tmp_path, monkeypatch, capsys):
    # tests run as root, where a read-only folder is writable: fail the renames instead
    import errno
    import os

    from mitsuba_mrt import imageio
    from mitsuba_mrt.app import cli

    real = os.replace

    def full_disk(src, dst):
        if str(dst).endswith(".png"):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        real(src, dst)

    monkeypatch.setattr(imageio.os, "replace", full_disk)
    code = cli.main(["render", str(SCENES / "paper_fraction.xml"), "-o", str(tmp_path / "out"),
                     "-D", "res=16", "--no-reference", "--mode", "fast"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.strip() == f"error: cannot write into {tmp_path / 'out'}: No space left on device"
    assert list((tmp_path / "out").iterdir()) == []


def test_negative_lights_are_one_warning_line_each(tmp_path):
    import re

    text = (SCENES / "paper_fraction.xml").read_text()
    scene = tmp_path / "negative.xml"
    scene.write_text(re.sub(r'name="intensity" value="[^"]*"', 'name="intensity" value="-5"',
                            text, count=1))
    proc = run_cli("render", scene, "-o", tmp_path / "out", "-D", "res=16", "--no-reference",
                   "--mode", "fast")
    assert proc.returncode == 0, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert lines == ["warning: emitter light_0 (PointLight) has a negative intensity (-5): "
                     "it subtracts light"]


def test_the_innermost_cause_is_reported():
    from mitsuba_mrt.app.cli import innermost

    try:
        try:
            raise RuntimeError("jit_var_shr(r0, r357): operands have incompatible sizes!")
        except RuntimeError as inner:
            raise RuntimeError("drjit.custom(...): error while performing a custom "
                               "differentiable operation. (see above).") from inner
    except RuntimeError as outer:
        assert str(innermost(outer)).startswith("jit_var_shr")
    plain = ValueError("x")
    assert innermost(plain) is plain

"""The ``batch`` command: values, tasks, and batches on Dask clusters (local and remote).

Clusters run on this machine only (127.0.0.1), with tiny matte renders.
"""

import contextlib
import io
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

from helpers import ROOT, SCENES
from mitsuba_mrt import MRTError
from mitsuba_mrt.app.batch import run_batch
from mitsuba_mrt.app.outputs import read_table
from mitsuba_mrt.app.sweep import Sweep, parse_values
from mitsuba_mrt.app.tasks import BatchTask, completed_row, plan_tasks

pytest.importorskip("distributed")

FIG1 = SCENES / "paper_fig1.xml"
ORBIT = SCENES / "paper_fig1_orbit.xml"
ENV = dict(os.environ, PYTHONPATH=os.pathsep.join(
    p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p))


@dataclass
class Ran:
    returncode: int
    stdout: str
    stderr: str


def run_cli(*args) -> Ran:
    """The command line, in this process (a second one would import Mitsuba again)."""
    from unittest import mock

    from mitsuba_mrt.app import cli

    out, err = io.StringIO(), io.StringIO()
    # configure() tunes the process it owns: not this one
    with mock.patch("mitsuba_mrt.runtime.configure", dict), \
            contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = cli.main([str(a) for a in args])
    return Ran(code, out.getvalue(), err.getvalue())


# -- values and tasks ----------------------------------------------------------------------


@pytest.mark.parametrize("text,values", [
    ("1", ["1"]),
    ("a,b", ["a", "b"]),
    (" path , matte ", ["path", "matte"]),
    ("0:360:90", ["0", "90", "180", "270"]),
    ("0:4", ["0", "1", "2", "3"]),
    ("10:0:-5", ["10", "5"]),
    ("0:1:0.25", ["0", "0.25", "0.5", "0.75"]),
    ("0:0.3:0.1", ["0", "0.1", "0.2"]),     # 0.3 / 0.1 rounds below 3: stop stays exclusive
    ("-0.5:0.5:0.5", ["-0.5", "0"]),
    ("1.5", ["1.5"]),
    ("0:60:30,90", ["0", "30", "90"]),
    ("", [""]),
])
def test_parse_values(text, values):
    assert parse_values(text) == values


@pytest.mark.parametrize("text,message", [
    ("0:10:0", "step of a range cannot be 0"),
    ("10:0:1", "is empty"),
    ("a:b:c", "needs numbers"),
    ("0:1:2:3", "start:stop:step"),
    ("1,,2", "empty value"),
    ("1,1", "given twice"),
    ("0:1e9:1", "more than"),
    ("0:inf:1", "needs numbers"),
])
def test_bad_values_are_one_line_errors(text, message):
    with pytest.raises(MRTError) as info:
        parse_values(text, "res")
    assert message in str(info.value) and "-D res=" in str(info.value)
    assert len(str(info.value).splitlines()) == 1


def test_tasks_are_the_product_with_one_folder_each():
    sweep = Sweep.parse([("res", "16"), ("azimuth", "0:60:30"), ("spp", "1,4")])
    tasks = plan_tasks([ORBIT, FIG1], sweep, {"mode": "fast"})
    assert len(tasks) == 2 * 2 * 2
    assert [t.name for t in tasks[:4]] == [
        "paper_fig1_orbit_azimuth=0_spp=1", "paper_fig1_orbit_azimuth=0_spp=4",
        "paper_fig1_orbit_azimuth=30_spp=1", "paper_fig1_orbit_azimuth=30_spp=4"]
    assert tasks[1].defines == {"res": "16", "azimuth": "0", "spp": "4"}
    assert tasks[1].varying == {"azimuth": "0", "spp": "4"}
    assert os.path.isabs(tasks[0].scene)
    assert [t.name for t in plan_tasks([FIG1], Sweep.parse([("res", "16")]))] == ["paper_fig1"]
    for defines, options, message in [
            ([("res", "16"), ("res", "24")], {}, "given twice"),
            ([], {"mode": "magic"}, "unknown mode"),
            ([], {"spp": 0}, "spp must be >= 1"),
            ([], {"spp": 2.5}, "spp must be an integer >= 1, got 2.5"),
            ([], {"seed": -1}, "seed must be an integer"),
            ([], {"param_overrides": {"sample_fraction": 2.0}}, "sample_fraction")]:
        with pytest.raises(MRTError, match=message):
            plan_tasks([FIG1], Sweep.parse(defines), options)
    with pytest.raises(MRTError, match="two scenes named"):
        plan_tasks([FIG1, "elsewhere/paper_fig1.xml"], Sweep())


def test_without_dask_one_line_and_exit_2(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "distributed", None)  # its import fails
    ran = run_cli("batch", FIG1, "-o", tmp_path / "out")
    assert ran.returncode == 2 and ran.stdout == ""
    assert ran.stderr == "error: the batch command needs Dask: pip install mitsuba-mrt[batch]\n"
    assert not (tmp_path / "out").exists()


def test_a_cluster_that_cannot_be_reached_leaves_no_output(monkeypatch, tmp_path):
    # (the table of pending tasks was written into a new folder: --scheduler tcp://nowhere:1)
    from mitsuba_mrt.app import batch

    @contextlib.contextmanager
    def unreachable(scheduler, workers, echo):
        raise MRTError(f"cannot connect to the Dask scheduler at {scheduler}: refused")
        yield
    monkeypatch.setattr(batch, "cluster_client", unreachable)
    with pytest.raises(MRTError, match="cannot connect"):
        run_batch([FIG1], tmp_path / "out", scheduler="tcp://127.0.0.1:1", echo=lambda line: None)
    assert not (tmp_path / "out").exists()
    (tmp_path / "kept").mkdir()  # a folder the user made stays, empty
    with pytest.raises(MRTError, match="cannot connect"):
        run_batch([FIG1], tmp_path / "kept", scheduler="tcp://127.0.0.1:1",
                  echo=lambda line: None)
    assert list((tmp_path / "kept").iterdir()) == []


# -- a batch on a local cluster --------------------------------------------------------------

SPREAD = ["-D", "res=16,24", "-D", "spp=1,4", "--mode", "fast"]


@pytest.fixture(scope="module")
def local_batch(tmp_path_factory):
    """fig1 and a malformed scene x 4 combinations, on a LocalCluster of 2 workers."""
    tmp = tmp_path_factory.mktemp("local")
    bad = tmp / "broken.xml"
    bad.write_text('<scene version="3.0.0"><shape type="sphere"></scene>')
    out = tmp / "out"
    start = time.perf_counter()
    proc = run_cli("batch", FIG1, bad, "-o", out, *SPREAD, "--workers", "2", "--no-progress")
    return out, proc, time.perf_counter() - start


def test_batch_equals_serial_renders(local_batch, tmp_path):
    from mitsuba_mrt.app.job import RenderJob, run_render_job

    out, proc, _ = local_batch
    jit = max(1, (os.cpu_count() or 1) // 2)  # each worker's share of this machine's cores
    assert (f"local cluster of 2 worker processes x 1 thread, Dr.Jit {jit} "
            f"thread{'s' if jit > 1 else ''} each") in proc.stdout
    for res in ("16", "24"):
        for spp in ("1", "4"):
            serial = tmp_path / f"{res}_{spp}"
            run_render_job(RenderJob(scene=str(FIG1), out_dir=str(serial), mode="fast",
                                     defines={"res": res, "spp": spp}))
            folder = out / f"paper_fig1_res={res}_spp={spp}"
            assert {p.name for p in folder.iterdir()} == {p.name for p in serial.iterdir()}
            for name in ("paper_fig1_mrt.exr", "paper_fig1_ref.exr"):
                assert (folder / name).read_bytes() == (serial / name).read_bytes(), name


def test_failed_task_is_a_row_and_the_batch_goes_on(local_batch):
    out, proc, _ = local_batch
    assert proc.returncode == 1
    assert "error: 4 of 8 tasks failed" in proc.stderr and "Traceback" not in proc.stderr
    rows = read_table(out / "batch.csv")
    assert list(rows[0]) == ["task", "scene", "res", "spp", "status", "message", "mode_used",
                             "traced_pixels", "pixels", "time_s", "reference_time_s",
                             "relative_time", "error", "psnr_db", "task_time_s", "worker"]
    good = [r for r in rows if r["task"].startswith("paper_fig1_")]
    bad = [r for r in rows if r["task"].startswith("broken_")]
    assert len(good) == len(bad) == 4
    for row in good:
        assert row["status"] == "ok" and row["message"] == "" and row["mode_used"] == "fast"
        assert int(row["traced_pixels"]) < int(row["pixels"]) == int(row["res"]) ** 2
        assert float(row["psnr_db"]) > 10 and float(row["task_time_s"]) > 0
    for row in bad:
        assert row["status"] == "failed" and "malformed XML" in row["message"]
        assert "\n" not in row["message"] and row["psnr_db"] == ""
        assert not (out / row["task"]).exists()  # nothing half-written
    assert not list(out.glob("*.gif"))  # two parameters vary: no animation


def test_rerun_skips_complete_tasks(local_batch, tmp_path):
    out = tmp_path / "out"
    shutil.copytree(local_batch[0], out)  # copy2: the mtimes are kept
    before = {p: p.stat().st_mtime_ns for p in out.rglob("*.exr")}
    lines = []
    result = run_batch([FIG1], out, [("res", "16,24"), ("spp", "1,4")], mode="fast",
                       progress=False, echo=lines.append)
    assert [r["status"] for r in result.rows] == ["skipped"] * 4
    assert not any(line.startswith("dask:") for line in lines)  # no cluster was started
    assert "4 already complete (skipped)" in lines[0]
    assert {p: p.stat().st_mtime_ns for p in out.rglob("*.exr")} == before
    assert [r["status"] for r in read_table(out / "batch.csv")] == ["skipped"] * 4
    assert read_table(out / "batch.csv")[0]["psnr_db"] != ""  # read back from the JSON


def test_a_changed_request_is_not_skipped(local_batch):
    out = local_batch[0]
    task = plan_tasks([FIG1], Sweep.parse([("res", "16"), ("spp", "1,4")]), {"mode": "fast"})[0]
    task = BatchTask("paper_fig1_res=16_spp=1", task.scene, {"res": "16", "spp": "1"},
                     {"res": "16", "spp": "1"}, task.job)
    assert completed_row(task, out)["status"] == "skipped"
    for change in ({"seed": 1}, {"mode": "paper"}, {"reference": False}, {"sensor": 1},
                   {"param_overrides": {"sample_fraction": 0.2}}):
        changed = BatchTask(task.name, task.scene, task.defines, task.varying,
                            {**task.job, **change})
        assert completed_row(changed, out) is None, change


# -- a cluster started with `dask scheduler` / `dask worker` ------------------------------------


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def remote_cluster(tmp_path_factory):
    """A scheduler and 2 worker processes (under a nanny), on 127.0.0.1."""
    from distributed import Client

    address = f"tcp://127.0.0.1:{_free_port()}"
    logs = tmp_path_factory.mktemp("dask-logs")
    dask = [sys.executable, "-m", "dask"]
    procs = []
    try:
        # each in its own process group: stopping it stops its nannies and workers too
        procs.append(subprocess.Popen(
            [*dask, "scheduler", "--host", "127.0.0.1", "--port", address.rsplit(":", 1)[1],
             "--no-dashboard"], env=ENV, cwd=ROOT, start_new_session=True,
            stdout=subprocess.DEVNULL, stderr=open(logs / "scheduler.log", "w")))
        procs.append(subprocess.Popen(
            [*dask, "worker", address, "--host", "127.0.0.1", "--nworkers", "2",
             "--nthreads", "1", "--no-dashboard", "--death-timeout", "60"], env=ENV, cwd=ROOT,
            start_new_session=True,
            stdout=subprocess.DEVNULL, stderr=open(logs / "worker.log", "w")))
        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=60)
            yield address, client
    finally:
        for proc in reversed(procs):
            os.killpg(proc.pid, signal.SIGKILL)  # its group: started above, ours alone
            proc.wait()


def test_scheduler_option_and_animation(remote_cluster, tmp_path):
    address, _ = remote_cluster
    out = tmp_path / "orbit"
    proc = run_cli("batch", ORBIT, "-o", out, "-D", "res=16", "-D", "azimuth=0:90:30",
                   "--scheduler", address, "--mode", "fast", "--no-reference",
                   "--no-progress")
    assert proc.returncode == 0, proc.stderr
    assert f"dask: scheduler {address}, 2 workers (2 threads)" in proc.stdout
    assert f"animation {out / 'paper_fig1_orbit.gif'}" in proc.stdout
    rows = read_table(out / "batch.csv")
    assert [r["azimuth"] for r in rows] == ["0", "30", "60"]
    assert all(r["status"] == "ok" for r in rows)
    import imageio.v3 as iio

    frames = iio.imread(out / "paper_fig1_orbit.gif", index=None)
    assert frames.shape[:3] == (3, 16, 16)  # in parameter order, one per azimuth
    first = iio.imread(out / "paper_fig1_orbit_azimuth=0" / "paper_fig1_orbit_mrt.png")
    assert abs(frames[0][..., :3].astype(int) - first[..., :3]).max() <= 8  # GIF palette


def _die_once(task_name: str, marker: str) -> None:
    """Run on every worker: task ``task_name`` kills its worker process the first time
    it runs, after leaving a temporary output file as a worker killed while writing
    would; ``marker`` (created once, with that process's id) says it has happened."""
    from mitsuba_mrt.app import tasks

    real = getattr(tasks.run_render_job, "real", tasks.run_render_job)

    def run_render_job(job):
        if Path(job.out_dir).name == task_name:
            try:
                fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
            except FileExistsError:  # it died once already: render
                pass
            else:
                os.write(fd, str(os.getpid()).encode())
                os.close(fd)
                folder = Path(job.out_dir)
                folder.mkdir(parents=True, exist_ok=True)
                (folder / f".{Path(job.scene).stem}_mrt.half.exr").write_bytes(b"half")
                os._exit(1)  # the worker process dies in the middle of the task
        return real(job)

    run_render_job.real = real
    tasks.run_render_job = run_render_job


def _live_again() -> None:
    """Undo :func:`_die_once` on a worker (one restarted since has nothing to undo)."""
    from mitsuba_mrt.app import tasks

    tasks.run_render_job = getattr(tasks.run_render_job, "real", tasks.run_render_job)


def test_killed_worker_loses_no_frame(remote_cluster, tmp_path):
    """A worker dies in the middle of a task, deterministically (no race against a
    deadline): that task runs again in another process and every frame is there."""
    address, client = remote_cluster
    out = tmp_path / "out"
    marker = tmp_path / "died"
    victim = "paper_fig1_orbit_azimuth=10"
    # the test module is not importable on the workers: send the hook by value
    cloudpickle = pytest.importorskip("cloudpickle")
    module = sys.modules[__name__]
    cloudpickle.register_pickle_by_value(module)
    try:
        client.run(_die_once, victim, str(marker))
        result = run_batch([ORBIT], out, [("res", "16"), ("azimuth", "0:40:10")],
                           scheduler=address, mode="fast", reference=False, progress=False,
                           echo=lambda line: None)
        client.wait_for_workers(2, timeout=60)  # the nanny brought the worker back
        client.run(_live_again)
    finally:
        cloudpickle.unregister_pickle_by_value(module)
    dead_pid = marker.read_text()  # the task did kill its worker
    assert [r["task"] for r in result.rows] == [f"paper_fig1_orbit_azimuth={a}"
                                                for a in (0, 10, 20, 30)]
    assert [r["status"] for r in result.rows] == ["ok"] * 4
    again = next(r for r in result.rows if r["task"] == victim)
    assert again["worker"].rsplit(":", 1)[1] != dead_pid  # it ran again, elsewhere
    for row in result.rows:
        assert (out / row["task"] / "paper_fig1_orbit_mrt.exr").exists()
        assert not list((out / row["task"]).glob(".*"))  # the leftover was removed


def worker_threads() -> tuple:
    """On a worker: Dr.Jit's threads, the package pool's, and what BLAS was told."""
    import drjit as dr

    from mitsuba_mrt.runtime import threads

    return dr.thread_count(), threads._pool()[1], os.environ.get("OPENBLAS_NUM_THREADS")


@pytest.mark.parametrize("workers", [1, 2])
def test_a_local_workers_threads_are_its_share_of_the_cores(workers):
    from mitsuba_mrt.app.cluster import cluster_map

    share = max(1, (os.cpu_count() or 1) // workers)
    with cluster_map(workers=workers, echo=lambda line: None) as map_calls:
        seen = {result for _, result in map_calls(worker_threads, [()] * (2 * workers))}
    assert seen == {(share, min(share, 8), str(share))}

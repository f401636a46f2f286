"""gfimu batch on Dask distributed: a scheduler and two workers started on localhost."""

import csv
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from live_net import env as _env

pytest.importorskip("dask.distributed")

from gfimu import io as gio  # noqa: E402
from gfimu.batch import output_folders  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def scheduler(tmp_path_factory):
    """``tcp://host:port`` of a scheduler with two single-threaded workers, torn down after the module."""
    folder = tmp_path_factory.mktemp("dask")
    info = folder / "scheduler.json"
    procs = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--scheduler-file", str(info),
                               "--port", "0", "--no-dashboard", "--host", "127.0.0.1"], env=_env(),
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        deadline = time.time() + 60
        while not info.exists() and time.time() < deadline:
            time.sleep(0.2)
        assert info.exists(), "the scheduler did not start"
        address = json.loads(info.read_text())["address"]
        for _ in range(2):
            procs.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1",
                                           "--nworkers", "1", "--no-dashboard", "--host", "127.0.0.1"], env=_env(),
                                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        from dask.distributed import Client

        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=60)
        yield address
    finally:
        for p in procs[::-1]:
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()


def test_output_folders_are_unique():
    """Folder names alone where they differ; the whole path's parts where they do not, so no name depends on the
    order of the logs or takes another log's (``log-2`` was once ``b/log``'s and ``c/log-2``'s)."""
    folders = output_folders(["a/log", "b/log", "c/other", "d/log"], "out")
    assert [f.name for f in folders] == ["a__log", "b__log", "other", "d__log"]
    folders = output_folders(["a/log", "b/log", "c/log-2"], "out")
    assert [f.name for f in folders] == ["a__log", "b__log", "log-2"]
    assert [f.name for f in output_folders(["x/a/log", "y/a/log", "z"], "out")] == ["x__a__log", "y__a__log", "z"]
    # the summary's name is kept for the summary
    assert [f.name for f in output_folders(["p/summary.csv", "q"], "out")] == ["p__summary.csv", "q"]


def test_output_folders_refuse_one_log_twice(tmp_path):
    from gfimu.io.errors import OutputError

    (tmp_path / "log").mkdir()
    with pytest.raises(OutputError, match="given twice"):
        output_folders([tmp_path / "log", str(tmp_path / "log") + "/"], "out")


def test_a_failed_log_points_at_no_output_even_when_an_earlier_estimate_is_there(tmp_path):
    """A log that worked once and is broken now: its row says failed with an empty output, not the path of the
    earlier run's estimate still in the folder."""
    from gfimu.batch import run_one
    from gfimu.simulate import simulate

    gio.write_log(simulate("reversal", duration_s=0.5, seed=1), tmp_path / "log")
    target = tmp_path / "out" / "log" / "estimate.csv"
    ok = run_one(str(tmp_path / "log"), str(target), "inversion", {}, None)
    assert ok["status"] == "ok" and ok["output"] == str(target) and target.is_file()
    (tmp_path / "log" / "imu.csv").write_text("#timestamp [ns],a1_x [m s^-2]\n0,abc\n")
    row = run_one(str(tmp_path / "log"), str(target), "inversion", {}, None)
    assert row["status"] == "failed" and row["output"] == "" and "imu.csv" in row["message"]


def test_a_log_argument_that_is_not_a_log_folder_is_a_failed_row_and_the_others_go_on(tmp_path):
    """`gfimu batch logs/*` catching a README file and a folder without array.toml: both are failed rows of
    the summary with their message, the real log is estimated, the exit status is 1."""
    from gfimu.simulate import simulate

    gio.write_log(simulate("reversal", duration_s=0.5, seed=1), tmp_path / "logs" / "log")
    (tmp_path / "logs" / "README").write_text("recorded on the bench\n")
    (tmp_path / "logs" / "notes").mkdir()
    logs = [str(tmp_path / "logs" / name) for name in ("README", "log", "notes")]
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "gfimu", "batch", *logs, "--out", str(out), "--method", "inversion",
                           "--workers", "1", "--quiet"], env=_env(), capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" not in proc.stderr and "README: failed" in proc.stderr and "notes: failed" in proc.stderr
    rows = list(csv.DictReader((out / "summary.csv").open()))
    assert [Path(r["log"]).name for r in rows] == ["README", "log", "notes"]
    assert [r["status"] for r in rows] == ["failed", "ok", "failed"]
    assert "not a log folder" in rows[0]["message"] and "no array.toml" in rows[2]["message"]
    assert "\n" not in rows[0]["message"] and rows[0]["output"] == "" and rows[2]["output"] == ""
    assert (out / "log" / "estimate.csv").is_file()
    assert sorted(p.name for p in out.iterdir()) == ["log", "summary.csv"]


def test_an_output_that_is_a_file_is_still_refused_before_any_log(tmp_path, capsys):
    """Refused before any log is read, the file left as it was (run in this process: a new one would
    only add the interpreter's start-up)."""
    from gfimu.cli import main

    (tmp_path / "out").write_text("")
    assert main(["batch", str(tmp_path / "README"), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "exists and is not a folder" in err and "Traceback" not in err and err.count("\n") == 1
    assert (tmp_path / "out").read_text() == ""


def _worker_environ():
    return {k: os.environ.get(k) for k in ("MALLOC_TRIM_THRESHOLD_", "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}


def test_local_workers_run_one_blas_thread_without_dasks_malloc_trim_threshold():
    """MALLOC_TRIM_THRESHOLD_=65536 (Dask's default for its workers) made the smoother 3x slower there."""
    from dask.distributed import Client

    from gfimu.batch import local_cluster

    cluster = local_cluster(1)
    try:
        with Client(cluster) as client:
            env = client.submit(_worker_environ, pure=False).result()
    finally:
        cluster.close()
    assert env == {"MALLOC_TRIM_THRESHOLD_": os.environ.get("MALLOC_TRIM_THRESHOLD_"), "OPENBLAS_NUM_THREADS": "1",
                   "OMP_NUM_THREADS": "1"}


@pytest.mark.slow
def test_batch_on_a_scheduler_with_two_workers(scheduler, tmp_path):
    """Three simulated logs and a broken one: each estimate equals gfimu estimate's on the same log,
    the summary has one row per log (the broken one failed, with its message) and the exit status is 1."""
    logs = []
    for seed, scenario in ((1, "reversal"), (2, "random3d"), (3, "turntable")):
        folder = tmp_path / f"{scenario}{seed}"
        from gfimu.simulate import simulate

        gio.write_log(simulate(scenario, duration_s=2.0, seed=seed), folder)
        logs.append(folder)
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "array.toml").write_text("this is not toml\n")
    (broken / "imu.csv").write_text("")
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "gfimu", "batch", *map(str, logs), str(broken), "--out", str(out),
                           "--scheduler", scheduler, "--quiet"], env=_env(), capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1, proc.stderr
    assert "broken: failed" in proc.stderr and proc.stdout == ""  # --quiet: no summary line, the failure stays
    rows = list(csv.DictReader((out / "summary.csv").open()))
    assert [Path(r["log"]).name for r in rows] == [p.name for p in logs] + ["broken"]
    assert [r["status"] for r in rows] == ["ok", "ok", "ok", "failed"]
    assert "not valid TOML" in rows[3]["message"] and not (out / "broken").exists()
    for log, row in zip(logs, rows):
        single = tmp_path / f"{log.name}.csv"
        assert subprocess.run([sys.executable, "-m", "gfimu", "estimate", str(log), "--out", str(single), "--no-progress"],
                              env=_env(), capture_output=True).returncode == 0
        a = gio.read_motion_csv(out / log.name / "estimate.csv")
        b = gio.read_motion_csv(single)
        np.testing.assert_allclose(a.omega_b_radps, b.omega_b_radps, rtol=0, atol=1e-9)
        truth = gio.read_log(log).truth.omega_b_radps
        rmse = float(np.sqrt(np.mean(np.sum((a.omega_b_radps - truth) ** 2, axis=1))))
        assert float(row["omega_rmse_radps"]) == pytest.approx(rmse, rel=1e-5)
        assert int(row["samples"]) == len(truth)


@pytest.mark.slow
def test_batch_refuses_an_unreachable_scheduler(tmp_path):
    from gfimu.simulate import simulate

    gio.write_log(simulate("reversal", duration_s=1.0, seed=1), tmp_path / "log")
    proc = subprocess.run([sys.executable, "-m", "gfimu", "batch", str(tmp_path / "log"), "--out", str(tmp_path / "out"),
                           "--scheduler", "tcp://127.0.0.1:9", "--quiet"], env=_env(), capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode != 0 and "Traceback" not in proc.stderr
    assert "scheduler" in proc.stderr.lower()

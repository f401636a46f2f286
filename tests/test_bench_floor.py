"""tools/bench_floor.py: the floor and the commands measured in one loop on a given log, the table of medians
and ratios it prints, and its refusals."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "tools" / "bench_floor.py"


def run(*args, cwd):
    return subprocess.run([sys.executable, str(SCRIPT), *args], capture_output=True, text=True, timeout=300, cwd=cwd)


def test_the_floor_and_a_command_in_one_loop_on_a_given_log(tmp_path):
    log = tmp_path / "log"
    done = subprocess.run([sys.executable, "-m", "gfimu", "simulate", "random3d", "--out", str(log), "--duration-s",
                           "0.5", "--quiet"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    done = run("--log", str(log), "--runs", "2", "--only", "floor,pass", "--json", str(tmp_path / "b.json"),
               cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "250 samples" in done.stdout
    assert "| floor: numpy + scipy.linalg, loadtxt imu.csv, savetxt 10 columns |" in done.stdout
    rows = [line for line in done.stdout.splitlines() if line.startswith("| floor:")]
    assert rows[0].split("|")[3].strip() == "1.00"  # the floor against itself
    res = json.loads((tmp_path / "b.json").read_text())["logs"]
    (entry,) = res.values()
    assert entry["samples"] == 250
    for name in ("floor", "pass"):
        assert len(entry[name]["walls_s"]) == 2
        assert entry[name]["wall_s"] == np.median(entry[name]["walls_s"]) and entry[name]["cpu_s"] > 0


def test_an_unknown_command_and_a_folder_without_a_log_are_refused(tmp_path):
    done = run("--only", "floor,speed", cwd=tmp_path)
    assert done.returncode == 2 and "no command 'speed'" in done.stderr and "fixed-lag" in done.stderr
    done = run("--log", str(tmp_path), cwd=tmp_path)
    assert done.returncode == 2 and f"--log {tmp_path}: no imu.csv" in done.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_baseline_checkout_runs_the_gfimu_commands_in_the_same_loop(tmp_path):
    log = tmp_path / "log"
    log.mkdir()
    (log / "imu.csv").write_text("#timestamp [ns],a\n0,1.0\n1000000,2.0\n")
    done = run("--log", str(log), "--runs", "1", "--only", "floor,import", "--baseline", str(REPO), "--json",
               str(tmp_path / "b.json"), cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert '| python -c "import gfimu.cli" [baseline] |' in done.stdout
    (entry,) = json.loads((tmp_path / "b.json").read_text())["logs"].values()
    assert sorted(entry) == ["floor", "import", "import@baseline", "samples"]
    done = run("--log", str(log), "--baseline", str(tmp_path), cwd=tmp_path)
    assert done.returncode == 2 and f"--baseline {tmp_path}: not a gfimu checkout" in done.stderr


@pytest.mark.slow
def test_a_cell_of_the_regime_matrix_is_built_and_measured(tmp_path):
    # --cell builds the cell's log (here 0.05 s of the 20 kHz impact cell: 1,000 samples) and measures on it
    done = run("--cell", "impacts-20kHz", "--duration-s", "0.05", "--runs", "1", "--only", "floor,pass", "--json",
               str(tmp_path / "b.json"), cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "regime-matrix cell impacts-20kHz (20000 Hz, 0.05 s): 1000 samples" in done.stdout
    done = run("--cell", "no-such-cell", cwd=tmp_path)
    assert done.returncode == 2 and "no cell 'no-such-cell'" in done.stderr

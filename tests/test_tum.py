"""TUM trajectories (``gfimu estimate --tum``): evo's reading of them, quaternion order and sign, exact timestamps."""

from __future__ import annotations

import csv
from decimal import Decimal

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gfimu.cli import main
from gfimu.io.trajectory import TUM_HEADER, seconds_text, write_tum
from gfimu.motion import Motion
from gfimu.rotations import matrix_from_quaternion


def read_like_evo(path):
    """(timestamp texts, float matrix) as evo's ``read_tum_trajectory_file`` parses them: comment lines
    starting with '#' skipped, fields split on single spaces, exactly 8 per row."""
    with open(path) as fh:
        rows = list(csv.reader((ln for ln in fh if not ln.startswith("#")), delimiter=" "))
    assert rows and all(len(r) == 8 for r in rows)
    return [r[0] for r in rows], np.array(rows).astype(float)


def test_written_file_reads_back_with_order_sign_and_exact_timestamps(tmp_path):
    rng = np.random.default_rng(3)
    n = 50
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[::2] *= -1.0  # both signs of the scalar part: the sign is kept as estimated
    stamps = 1_700_000_000_123_456_789 + np.arange(n, dtype=np.int64) * 2_000_001
    motion = Motion(stamps, quaternion_wb=q)
    path = tmp_path / "traj.tum"
    assert write_tum(motion, path) == n
    assert path.read_text().splitlines()[0] == TUM_HEADER
    times, mat = read_like_evo(path)
    # timestamps: exact decimal seconds of the nanoseconds (a float would lose the last digits)
    assert [int(Decimal(t) * 10**9) for t in times] == stamps.tolist()
    assert times[0] == "1700000000.123456789"
    np.testing.assert_array_equal(mat[:, 1:4], 0.0)
    # qx qy qz qw: the estimate's q_x, q_y, q_z, q_w, same sign, exactly
    np.testing.assert_array_equal(mat[:, 4:8], np.column_stack([q[:, 1:4], q[:, 0]]))
    # scipy's scalar-last quaternion of each row is the body->world rotation: R v_B = v_W
    r_scipy = Rotation.from_quat(mat[:, 4:8]).as_matrix()
    # two formulas of the matrix of a unit quaternion (entries of order 1, a few products each): 16 ε
    np.testing.assert_allclose(r_scipy, matrix_from_quaternion(q), atol=16 * np.finfo(float).eps)
    v_b = np.array([1.0, 2.0, 3.0])
    np.testing.assert_allclose(Rotation.from_quat(mat[0, 4:8]).apply(v_b), matrix_from_quaternion(q[0]) @ v_b,
                               atol=1e-14)


def test_known_rotation_and_negative_time():
    # 90 degrees about world z: body x points along world y
    q = np.array([[np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4)]])
    r = Rotation.from_quat(np.r_[q[0, 1:], q[0, 0]])
    np.testing.assert_allclose(r.apply([1.0, 0.0, 0.0]), [0.0, 1.0, 0.0], atol=16 * np.finfo(float).eps)
    assert seconds_text(np.array([-1, 0, 1_000_000_000, -2_500_000_000])) == [
        "-0.000000001", "0.000000000", "1.000000000", "-2.500000000"]


def test_non_finite_rows_are_left_out_and_no_attitude_is_refused(tmp_path):
    q = np.tile([1.0, 0.0, 0.0, 0.0], (4, 1))
    q[2] = np.nan
    assert write_tum(Motion(np.arange(4) * 10, quaternion_wb=q), tmp_path / "a.tum") == 3
    times, _ = read_like_evo(tmp_path / "a.tum")
    assert times == ["0.000000000", "0.000000010", "0.000000030"]
    with pytest.raises(ValueError, match="no orientation"):
        write_tum(Motion(np.arange(4), omega_b_radps=np.zeros((4, 3))), tmp_path / "b.tum")
    assert not (tmp_path / "b.tum").exists()


@pytest.fixture(scope="module")
def log_dir(tmp_path_factory):
    work = tmp_path_factory.mktemp("tum")
    assert main(["simulate", "reversal", "--out", str(work / "log"), "--duration-s", "0.4", "--quiet"]) == 0
    return work


def test_estimate_writes_the_tum_file_of_its_orientation(log_dir, capsys):
    est, tum = log_dir / "est.csv", log_dir / "est.tum"
    assert main(["estimate", str(log_dir / "log"), "--method", "ml", "--orientation", "estimate",
                 "--out", str(est), "--tum", str(tum), "--quiet"]) == 0
    from gfimu import io as gio

    motion = gio.read_motion_csv(est)
    times, mat = read_like_evo(tum)
    assert [int(Decimal(t) * 10**9) for t in times] == motion.timestamps_ns.tolist()
    q = motion.quaternion_wb
    np.testing.assert_array_equal(mat[:, 4:8], np.column_stack([q[:, 1:4], q[:, 0]]))


def test_estimate_refuses_tum_without_orientation(log_dir, capsys):
    est, tum = log_dir / "e2.csv", log_dir / "e2.tum"
    assert main(["estimate", str(log_dir / "log"), "--method", "ml", "--out", str(est), "--tum", str(tum)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--tum" in err and "--orientation" in err
    assert not est.exists() and not tum.exists()
    assert main(["estimate", str(log_dir / "log"), "--method", "ml", "--orientation", "estimate",
                 "--out", str(est), "--tum", str(est)]) == 2
    assert "the same file as --out" in capsys.readouterr().err and not est.exists()

"""imu.csv and motion CSVs read in blocks: the same arrays and the same errors (file and line) whatever the
block size, so a block boundary never changes an answer."""

import numpy as np
import pytest

from gfimu.array import cube_array
from gfimu.io import tables
from gfimu.io.errors import LogFormatError
from gfimu.log import Log

ARRAY = cube_array(0.05, 0.07)
BLOCKS = [16, 100, 1 << 22]  # smaller than a line, a few lines, the whole file


@pytest.fixture(params=BLOCKS, ids=lambda b: f"block{b}")
def block(request, monkeypatch):
    monkeypatch.setattr(tables, "_BLOCK_BYTES", request.param)
    return request.param


def written(tmp_path, n=57):
    rng = np.random.default_rng(1)
    t = 1_000_000_000 + np.arange(n, dtype=np.int64) * 2_000_000
    y = rng.normal(0, 3, (n, ARRAY.n_axes))
    path = tmp_path / "imu.csv"
    tables.write_imu_csv(Log(ARRAY, t, y), path)
    return path, t, y


def lines_of(path):
    return path.read_text().split("\n")


def test_values_and_timestamps_identical_for_every_block_size(tmp_path, block):
    path, t, y = written(tmp_path)
    t2, y2, gyro, tilt = tables.read_imu_csv(path, ARRAY)
    np.testing.assert_array_equal(t2, t)
    np.testing.assert_allclose(y2, y, rtol=1e-12, atol=1e-12)
    assert gyro is None and tilt is None


def test_crlf_line_ends_and_trailing_empty_lines(tmp_path, block):
    path, t, y = written(tmp_path)
    path.write_bytes(path.read_bytes().replace(b"\n", b"\r\n") + b"\r\n\r\n")
    t2, y2, _, _ = tables.read_imu_csv(path, ARRAY)
    np.testing.assert_array_equal(t2, t)
    np.testing.assert_allclose(y2, y, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("row", [0, 31, 56])
def test_errors_name_the_same_line_whatever_the_block(tmp_path, block, row):
    path, t, _ = written(tmp_path)
    lines = lines_of(path)
    line = row + 2  # 1-based, after the header

    def expect(new_line, match):
        ls = list(lines)
        ls[line - 1] = new_line
        path.write_text("\n".join(ls))
        with pytest.raises(LogFormatError) as err:
            tables.read_imu_csv(path, ARRAY)
        assert f"imu.csv:{line}:" in str(err.value) and match in str(err.value), str(err.value)

    original = lines[line - 1]
    fields = original.split(",")
    expect(",".join(fields[:-1]), "has 12 fields, the header has 13")
    expect(",".join(fields[:3] + ["abc"] + fields[4:]), "value 'abc' is not a number")
    if row > 0:
        expect(",".join([lines[line - 2].split(",")[0]] + fields[1:]), "is not after the previous one")
    if row < 56:
        expect("", "row is empty, the header has 13 (ragged rows: 1)")


def test_non_finite_value_is_named_in_motion_tables(tmp_path, block):
    from gfimu.io import read_motion_csv
    from gfimu.motion import Motion

    n = 40
    t = np.arange(n, dtype=np.int64) * 1_000_000
    w = np.random.default_rng(2).normal(size=(n, 3))
    path = tmp_path / "truth.csv"
    tables.write_motion_csv(Motion(t, omega_b_radps=w), path)
    np.testing.assert_allclose(read_motion_csv(path).omega_b_radps, w, rtol=1e-12, atol=1e-12)
    lines = lines_of(path)
    fields = lines[30].split(",")
    fields[2] = "nan"
    lines[30] = ",".join(fields)
    path.write_text("\n".join(lines))
    with pytest.raises(LogFormatError, match=r"truth.csv:31: column 'w_y' is 'nan'.*1 non-finite"):
        read_motion_csv(path)


def test_bad_utf8_names_its_line_across_blocks(tmp_path, block):
    path, _, _ = written(tmp_path)
    raw = bytearray(path.read_bytes())
    at = raw.index(b"\n", len(raw) // 2) + 1  # start of some line
    line = raw[:at].count(b"\n") + 1
    raw[at:at + 1] = b"\xff"
    path.write_bytes(bytes(raw))
    with pytest.raises(LogFormatError, match=rf"imu.csv:{line}: not UTF-8 text \(byte {at}\)"):
        tables.read_imu_csv(path, ARRAY)


@pytest.mark.parametrize("cell, message", [
    (None, None),
    ("0.5", r"reference.csv:31: column 'valid' is 0\.5; expected 1 \(valid\) or 0 \(invalid\)"),
    ("nan", r"reference.csv:31: column 'valid' is 'nan'; values must be finite"),
    ("x", r"reference.csv:31: column 'valid' \(field 5\) value 'x' is not a number"),
])
def test_reference_valid_column_whatever_the_block(tmp_path, block, cell, message):
    """A reference whose gyro saturated (NaN where valid is 0) reads the same in any blocks, and a
    wrong 'valid' cell is named on its line."""
    from gfimu.io import read_motion_table

    n = 40
    t = np.arange(n, dtype=np.int64) * 1_000_000
    w = np.random.default_rng(4).normal(size=(n, 3))
    valid = np.ones(n, dtype=int)
    valid[[5, 6, 20]] = 0
    wl = w.tolist()
    rows = [f"{t[k]},{wl[k][0]!r},{'nan' if not valid[k] else repr(wl[k][1])},{wl[k][2]!r},{valid[k]}" for k in range(n)]
    if cell is not None:
        rows[29] = ",".join(rows[29].split(",")[:4] + [cell])
    path = tmp_path / "reference.csv"
    path.write_text("#timestamp [ns],w_x [rad s^-1],w_y [rad s^-1],w_z [rad s^-1],valid []\n" + "\n".join(rows) + "\n")
    if message is not None:
        with pytest.raises(LogFormatError, match=message):
            read_motion_table(path)
        return
    motion, ok = read_motion_table(path)
    assert ok.tolist() == (valid == 1).tolist()
    np.testing.assert_array_equal(motion.omega_b_radps[ok], w[ok])
    assert np.all(np.isnan(motion.omega_b_radps[~ok, 1]))
    rows[12] = rows[12].replace(f",{wl[12][1]!r},", ",nan,")  # not finite where valid is 1: named
    path.write_text("#timestamp [ns],w_x [rad s^-1],w_y [rad s^-1],w_z [rad s^-1],valid []\n" + "\n".join(rows) + "\n")
    with pytest.raises(LogFormatError, match=r"reference.csv:14: column 'w_y' is 'nan'; values must be finite where valid is 1"):
        read_motion_table(path)

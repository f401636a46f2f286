"""One rule for timestamp tokens (gfimu.io.units.timestamps_ns): a gfimu log's imu.csv (gfimu.io.tables) and a
CSV read by a column map (gfimu.io.readers.csv) give the same nanoseconds for the same tokens, and refuse the
same bad tokens with the same words, naming the file and the line."""

from pathlib import Path

import numpy as np
import pytest

from gfimu import io as gio
from gfimu.io.readers.csv import read_csv_recording
from gfimu.io.units import TimestampError, same_nanosecond, timestamp_ns, timestamps_ns

MAP = 'format = "gfimu-csv-map/1"\n[time]\ncolumn = "t"\n[[accelerometers]]\nname = "a"\nx = "ax"\ny = "ay"\nz = "az"\n'
SCALE = {"s": 10**9, "ms": 10**6, "us": 10**3, "ns": 1}
ARRAY = ('format = "gfimu-array/1"\n[[accelerometers]]\nname = "a"\nposition_m = [0, 0, 0]\n')


def by_both_readers(tmp_path: Path, unit: str, tokens: list[str]):
    """(times from the gfimu log reader, times from the CSV reader) of the same time tokens, or the
    LogFormatError each raised."""
    rows = "".join(f"{t},0,0,1\n" for t in tokens)
    log_dir = tmp_path / "log"
    log_dir.mkdir(exist_ok=True)
    (log_dir / "array.toml").write_text(ARRAY, encoding="utf-8")
    (log_dir / "imu.csv").write_text(f"#timestamp [{unit}],a_x [m s^-2],a_y [m s^-2],a_z [m s^-2]\n{rows}",
                                     encoding="utf-8")
    (tmp_path / "f.csv").write_text(f"t [{unit}],ax [m s^-2],ay [m s^-2],az [m s^-2]\n{rows}", encoding="utf-8")
    (tmp_path / "map.toml").write_text(MAP, encoding="utf-8")
    out = []
    for read in (lambda: gio.read_log(log_dir, check=False),
                 lambda: read_csv_recording(str(tmp_path / "f.csv"), str(tmp_path / "map.toml")).log):
        try:
            out.append(read().timestamps_ns)
        except gio.LogFormatError as exc:
            out.append(exc)
    return out


@pytest.mark.filterwarnings("ignore")  # uneven steps: rate and gap warnings are not the point here
@pytest.mark.parametrize("unit, tokens, expected", [
    # fractional seconds, exact from the decimal text, a half nanosecond to the even one
    ("s", ["0.5", "1.0000000015", "1.0000000035", "2", "2.5e0", "1E1"],
     [500_000_000, 1_000_000_002, 1_000_000_004, 2_000_000_000, 2_500_000_000, 10_000_000_000]),
    ("ms", ["0", "2.0000005", "4.0000015", "6", "8.0000025"], [0, 2_000_000, 4_000_002, 6_000_000, 8_000_002]),
    ("us", [" 1 ", "+2.0005", "3.0015"], [1_000, 2_000, 3_002]),
    # integer nanosecond stamps (EuRoC), read at once, and with a fraction of a nanosecond among them
    ("ns", ["1403715273262142976", "1403715273267142912", "1403715273272143104"],
     [1403715273262142976, 1403715273267142912, 1403715273272143104]),
    ("ns", ["1403715273262142976", "1403715273267142912.5", "1403715273272143103.5", "-0"],
     None),  # a step back at the end: refused by both (checked below)
    ("ns", ["-20.5", "-11.5", "12.6"], [-20, -12, 13]),
])
def test_both_readers_give_the_same_times(tmp_path, unit, tokens, expected):
    from_log, from_csv = by_both_readers(tmp_path, unit, tokens)
    if expected is None:
        assert isinstance(from_log, gio.LogFormatError) and isinstance(from_csv, gio.LogFormatError)
        assert from_log.line == from_csv.line and "not after" in str(from_log) and "not after" in str(from_csv)
        return
    assert isinstance(from_log, np.ndarray), from_log
    assert isinstance(from_csv, np.ndarray), from_csv
    assert from_log.dtype == from_csv.dtype == np.int64
    assert from_log.tolist() == from_csv.tolist() == expected
    assert timestamps_ns(tokens, SCALE[unit]).tolist() == [timestamp_ns(t, SCALE[unit]) for t in tokens] == expected


@pytest.mark.parametrize("unit, bad, words", [
    ("s", "x", "timestamp 'x' is not a number"),
    ("s", "", "timestamp '' is not a number"),
    ("ms", "nan", "timestamp 'nan' is not a finite number"),
    ("s", "-inf", "timestamp '-inf' is not a finite number"),
    ("s", "1e400", "timestamp '1e400' is out of range for 64-bit nanoseconds"),
    ("s", "9223372037", "timestamp '9223372037' is out of range for 64-bit nanoseconds"),
    ("ns", "9223372036854775808", "timestamp '9223372036854775808' is out of range for 64-bit nanoseconds"),
    ("ns", "0x10", "timestamp '0x10' is not a number"),
])
def test_a_bad_token_is_named_with_its_file_and_line_by_both_readers(tmp_path, unit, bad, words):
    tokens = ["1", "2", bad, "4"]
    from_log, from_csv = by_both_readers(tmp_path, unit, tokens)
    for exc, name in ((from_log, "imu.csv"), (from_csv, "f.csv")):
        assert isinstance(exc, gio.LogFormatError), exc
        assert exc.path.endswith(name) and exc.line == 4, (exc.path, exc.line)
        assert words in str(exc) and str(exc).startswith(f"{exc.path}:4: "), str(exc)
    with pytest.raises(TimestampError, match=words) as info:
        timestamps_ns(tokens, SCALE[unit])
    assert info.value.index == 2


def test_seconds_under_a_nanosecond_header_point_at_the_unit_in_both_readers(tmp_path):
    """Distinct increasing times that round to one nanosecond are refused as a unit too coarse, not a step back."""
    from_log, from_csv = by_both_readers(tmp_path, "ns", ["1403715273.262143", "1403715273.267143"])
    for exc in (from_log, from_csv):
        assert isinstance(exc, gio.LogFormatError) and exc.line == 3
        assert "are the same nanosecond in [ns]; is the time unit right?" in str(exc), str(exc)
    assert same_nanosecond("1.2", "1.3") and not same_nanosecond("1.3", "1.2") and not same_nanosecond("1", " 1")
    assert not same_nanosecond("x", "1")


def test_the_rule_does_not_depend_on_the_callers_decimal_context():
    import decimal

    with decimal.localcontext() as ctx:
        ctx.prec, ctx.rounding = 5, decimal.ROUND_UP
        assert timestamp_ns("1403715273.2621429765", 10**9) == 1403715273262142976
        assert timestamp_ns("2.5", 1) == 2 and timestamp_ns("3.5", 1) == 4 and timestamp_ns("-2.5", 1) == -2

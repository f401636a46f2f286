"""MIMU4444 decoder: synthetic byte streams with exact expected counts, and the real recordings."""

import struct

import numpy as np
import pytest

from gfimu.io.readers import mimu4444 as m


def make_packet(counter: int, ticks: int, raw: np.ndarray, corrupt_checksum: bool = False) -> bytes:
    body = struct.pack(">BHBI", 0xAA, counter % 65536, 100, ticks % (1 << 32)) + np.asarray(raw, ">i2").tobytes()
    assert len(body) == 104
    csum = sum(body) % 65536
    if corrupt_checksum:
        csum = (csum + 1) % 65536
    return body + struct.pack(">H", csum)


def raw_for(k: int) -> np.ndarray:
    """Distinct counts per packet: accel = k on every axis (sign varies), gyro = 10 k."""
    r = np.zeros((8, 6), dtype=np.int16)
    r[:, 0:3] = (k % 1000) + np.arange(3)
    r[:, 3:6] = -((k % 1000) * 10)
    return r


def test_clean_stream_counts_and_time():
    start_ticks = (1 << 32) - 3 * 1_024_000  # timestamp wraps after the third packet
    pk = [make_packet(65534 + k, start_ticks + k * 1_024_000, raw_for(k)) for k in range(6)]  # counter wraps too
    rec = m.decode(b"".join(pk))
    r = rec.report
    assert (r.n_packets, r.skipped_bytes, r.bad_checksums, r.dropped_packets, r.counter_gaps, r.time_gaps) == (6, 0, 0, 0, 0, 0)
    assert np.all(np.diff(rec.timestamps_ns) == 16_000_000)
    assert r.duration_s == pytest.approx(0.080)


def test_stray_bytes_bad_checksum_dropped_packet_and_wrap():
    t0 = (1 << 32) - 2 * 1_024_000 - 17
    packets = {k: make_packet(65533 + k, t0 + k * 1_024_000, raw_for(k)) for k in range(10)}
    stream = bytearray(b"\x01\xaa\x00\x05\x64")  # 5 stray bytes holding a false header with the length byte at +3
    stream += packets[0] + packets[1]
    stream += b"\xaa\xaa\x17"  # 3 stray bytes between packets
    stream += packets[2]
    stream += make_packet(65533 + 3, t0 + 3 * 1_024_000, raw_for(3), corrupt_checksum=True)  # 106 corrupt bytes
    stream += packets[4]
    # packet 5 is dropped (never sent)
    stream += packets[6] + packets[7] + packets[8] + packets[9]
    stream += packets[9][:50]  # truncated tail
    rec = m.decode(bytes(stream))
    r = rec.report
    assert r.n_packets == 8
    assert r.bad_checksums == 2  # the false header in the leading stray bytes and the corrupt packet
    assert r.skipped_bytes == 5 + 3 + 106 + 50
    assert r.skipped_regions == 4
    assert r.dropped_packets == 2  # packet 3 (corrupt) and packet 5 (missing)
    assert r.counter_gaps == 2
    assert r.time_gaps == 2
    assert r.gap_indices == (3, 4)
    # timestamps across the 32-bit tick wrap: 16 ms per packet, 32 ms over each gap
    assert np.diff(rec.timestamps_ns).tolist() == [16_000_000, 16_000_000, 32_000_000, 32_000_000] + [16_000_000] * 3
    # payload decoded from the right packets: accel x count of IMU 1 (not rotated) is k
    kept = [0, 1, 2, 4, 6, 7, 8, 9]
    assert np.allclose(rec.accel_b_mps2[:, 0, 0], np.array(kept) * m.ACCEL_MPS2_PER_COUNT)


def test_duplicate_packet_removed():
    pk = [make_packet(k, 1000 + k * 1_024_000, raw_for(k)) for k in range(4)]
    rec = m.decode(pk[0] + pk[1] + pk[1] + pk[2] + pk[3])
    assert rec.report.n_packets == 4 and rec.report.duplicates_removed == 1


def test_gap_longer_than_tick_wrap_uses_counter():
    # 5000 packets dropped = 80 s > the 67.1 s tick wrap
    pk = [make_packet(0, 0, raw_for(0)), make_packet(1, 1_024_000, raw_for(1)),
          make_packet(5002, 5002 * 1_024_000, raw_for(2)), make_packet(5003, 5003 * 1_024_000, raw_for(3))]
    rec = m.decode(b"".join(pk))
    assert rec.report.dropped_packets == 5000
    assert rec.timestamps_ns[2] == 5002 * 16_000_000


def test_board_frame_rotation_and_scaling():
    raw = np.zeros((1, 8, 6), dtype=np.int16)
    raw[0, :, 0:3] = [2048, 0, 0]  # +1 g on sensor x
    raw[0, :, 3:6] = [0, 164, 0]  # 10 deg/s on sensor y
    acc, gyr = m.board_frame(raw)
    g = 9.80665
    for i in range(8):
        if i in (1, 3, 5, 7):  # upside down: board = C · sensor
            assert np.allclose(acc[0, i], [0, -g, 0]) and np.allclose(gyr[0, i], [-np.deg2rad(10), 0, 0])
        else:
            assert np.allclose(acc[0, i], [g, 0, 0]) and np.allclose(gyr[0, i], [0, np.deg2rad(10), 0])


def test_saturation_mask():
    raw = np.zeros((6, 8, 6), dtype=np.int16)
    raw[2, 5, 4] = 32767
    raw[4, 0, 3] = -32768
    raw[1, 3, 5] = 32766
    clipped, invalid = m.saturation_mask(raw)
    assert clipped.tolist() == [False, False, True, False, True, False]
    _, wide = m.saturation_mask(raw, margin=1)
    assert wide.tolist() == [False, True, True, True, True, True]


def test_garbage_raises():
    with pytest.raises(m.MIMU4444FormatError, match="no MIMU4444 packet"):
        m.decode(bytes(range(256)) * 3)


def test_log_from_synthetic_stream():
    k = np.arange(5)
    pk = []
    for i in k:
        raw = raw_for(int(i))
        raw[:, 3:6] = [164 * i, 0, 0]  # 10 i deg/s on every sensor's x axis
        pk.append(make_packet(int(i), int(i) * 1_024_000, raw))
    log = m.to_log(m.decode(b"".join(pk)), with_gyro=True)
    assert log.accel_mps2.shape == (5, 24) and log.array.accel_columns[:3] == ["imu1_x", "imu1_y", "imu1_z"]
    # upright sensors give (w, 0, 0), upside-down ones C·(w, 0, 0) = (0, -w, 0): the mean is (w/2, -w/2, 0)
    w = np.deg2rad(10.0 * k)
    assert np.allclose(log.reference.omega_b_radps, np.column_stack([w / 2, -w / 2, 0 * w]))
    assert np.allclose(log.gyro_b_radps, log.reference.omega_b_radps)
    assert log.invalid_reference.tolist() == [False] * 5


def test_exp1_decodes(mimu4444_dir):
    log, rep = m.read_mimu4444(mimu4444_dir / "exp_1" / "data.bin", with_gyro=True)
    assert rep.n_packets == 37439 == len(log)
    assert rep.dropped_packets == 0 and rep.counter_gaps == 0 and rep.time_gaps == 0 and rep.bad_checksums == 0
    assert rep.duration_s == pytest.approx(599.0, abs=0.5)
    assert log.rate_hz == pytest.approx(62.5, rel=1e-3)
    share = rep.invalid_reference_samples / rep.n_packets
    assert 0.02 < share < 0.04  # README: about 3 % saturated
    # the first samples are still: every accelerometer reads |f| ≈ g in the board frame, all eight agree
    f = log.accel_mps2[:60].reshape(60, 8, 3).mean(axis=0)
    assert np.allclose(np.linalg.norm(f, axis=1), 9.81, atol=0.4)
    assert np.max(np.linalg.norm(f - f.mean(axis=0), axis=1)) < 1.0
    assert np.linalg.norm(log.reference.omega_b_radps[:60].mean(axis=0)) < 0.05


def test_convert_cli_round_trip(tmp_path, capsys):
    from gfimu import io as gio
    from gfimu.cli import main

    raw = [raw_for(k) for k in range(8)]
    raw[5][3, 4] = 32767  # one gyro axis clipped at sample 4 (packet 5, after the dropped packet 3)
    pk = [make_packet(k, 7 + k * 1_024_000, raw[k]) for k in range(8) if k != 3]
    src = tmp_path / "data.bin"
    src.write_bytes(b"\x00\x01" + b"".join(pk))
    out = tmp_path / "log"
    assert main(["convert", "mimu4444", str(src), "--out", str(out), "--with-gyro"]) == 0
    text = capsys.readouterr().out
    assert "packets: 7 decoded" in text and "dropped: 1 packet(s) in 1 counter gap(s); 1 time gap(s)" in text
    assert "reference marked invalid on 1 sample(s)" in text
    with pytest.warns(UserWarning, match="1 gap"):
        log = gio.read_log(out)
    assert len(log) == 7 and log.gyro_b_radps is not None
    assert log.invalid_reference.tolist() == [False, False, False, False, True, False, False]
    assert np.allclose(log.accel_mps2[:, 0], np.array([0, 1, 2, 4, 5, 6, 7]) * m.ACCEL_MPS2_PER_COUNT)
    assert [g.index for g in log.gaps()] == [3]
    # without --with-gyro there are no gyro channels, the reference is still there
    assert main(["convert", "mimu4444", str(src), "--out", str(tmp_path / "log2")]) == 0
    with pytest.warns(UserWarning, match="1 gap"):
        log2 = gio.read_log(tmp_path / "log2")
    assert log2.gyro_b_radps is None and np.allclose(log2.reference.omega_b_radps, log.reference.omega_b_radps)


def test_convert_cli_bad_input(tmp_path, capsys):
    from gfimu.cli import main

    src = tmp_path / "data.bin"
    src.write_bytes(bytes(500))
    assert main(["convert", "mimu4444", str(src), "--out", str(tmp_path / "log")]) == 2
    assert "no MIMU4444 packet" in capsys.readouterr().err


def test_shift_reference_resamples_and_widens_invalid():
    from gfimu.array import mimu4444_array
    from gfimu.log import Log
    from gfimu.motion import Motion

    n = 200
    t = np.arange(n) * 16_000_000
    ts = t * 1e-9
    w = np.column_stack([np.sin(3 * ts), np.cos(2 * ts), ts**2])
    invalid = np.zeros(n, bool)
    invalid[100] = True
    log = Log(mimu4444_array(), t, np.zeros((n, 24)), reference=Motion(t, omega_b_radps=w), invalid_reference=invalid)
    out = m.shift_reference(log, -1.5)
    expected = np.column_stack([np.sin(3 * (ts - 1.5e-3)), np.cos(2 * (ts - 1.5e-3)), (ts - 1.5e-3) ** 2])
    ok = ~out.invalid_reference
    assert np.max(np.abs(out.reference.omega_b_radps[ok] - expected[ok])) < 1e-5
    assert np.nonzero(out.invalid_reference)[0].tolist() == [0, 100, 101]
    assert np.nonzero(m.shift_reference(log, 1.0).invalid_reference)[0].tolist() == [99, 100, 199]
    assert m.shift_reference(log, 0.0) is log


def test_convert_cli_reference_shift(tmp_path, capsys):
    from gfimu import io as gio
    from gfimu.cli import main

    pk = []
    for k in range(12):
        raw = raw_for(k)
        raw[:, 3:6] = [16 * k * k, 0, 0]  # ω_x grows quadratically
        pk.append(make_packet(k, k * 1_024_000, raw))
    src = tmp_path / "data.bin"
    src.write_bytes(b"".join(pk))
    assert main(["convert", "mimu4444", str(src), "--out", str(tmp_path / "log"), "--reference-shift-ms", "-1.5"]) == 0
    assert "reference re-sampled at t -1.5 ms; invalid on 1 sample(s)" in capsys.readouterr().out
    log = gio.read_log(tmp_path / "log")
    k = np.arange(12)
    wx = np.deg2rad(16 * (k - 1.5 / 16) ** 2 / 16.4) / 2  # mean of upright (x) and flipped (−y) sensors
    assert np.allclose(log.reference.omega_b_radps[1:, 0], wx[1:], atol=1e-9)
    assert log.invalid_reference.tolist() == [True] + [False] * 11


def _stream(counters) -> list:
    """The streaming decoder fed one packet per chunk with the given counters (ticks follow them)."""
    decoder = m.StreamDecoder()
    said = []
    for k, c in enumerate(counters):
        decoder.feed(make_packet(int(c), int(c) * 1_024_000, raw_for(k)))
        message = decoder.disorder()
        if message is not None:
            said.append((k, message))
    return decoder, said


def test_stream_decoder_names_a_counter_that_does_not_count_once():
    rng = np.random.default_rng(7)
    decoder, said = _stream(rng.integers(0, 65536, 300))
    assert len(said) == 1  # said once, at the first packet it may be judged on
    k, message = said[0]
    assert k == m.STREAM_DISORDER_PACKETS - 1
    assert message.startswith("the packet counter does not count:")
    assert decoder.packets == 300 and decoder.duplicates + decoder.counter_gaps > 0.9 * 299


def test_stream_decoder_quiet_on_a_counting_stream_with_a_few_losses():
    counters = [c for c in range(400) if c not in (5, 6, 50, 300)]  # four packets lost, two gaps
    decoder, said = _stream(counters)
    assert said == [] and decoder.counter_gaps == 3 and decoder.duplicates == 0 and decoder.packets == 396

"""Sensors in different files brought onto one time base (:func:`align`): linear interpolation over the
span all files share, never across a gap of a file, or onto a uniform grid.
"""

from __future__ import annotations

import numpy as np

from ...errors import LogFormatError
from ...time_grid import GAP_FACTOR, find_gaps, interpolate, nominal_rate_hz, uniform_grid


def resample_linear(t_src_ns: np.ndarray, values: np.ndarray, t_dst_ns: np.ndarray) -> np.ndarray:
    """``values`` (N, k) sampled at ``t_src_ns`` linearly interpolated at ``t_dst_ns`` (inside the source span)."""
    t0 = t_dst_ns[0]
    src = (np.asarray(t_src_ns, dtype=np.int64) - t0).astype(float)
    dst = (np.asarray(t_dst_ns, dtype=np.int64) - t0).astype(float)
    values = np.asarray(values, dtype=float).reshape(len(src), -1)
    return np.column_stack([np.interp(dst, src, values[:, j]) for j in range(values.shape[1])])


MAX_SHOWN_GAPS = 5
"""Gaps listed one by one in the report; the others are counted."""


def align(groups: dict, blocks: list, base_key: tuple, tables: dict, max_gap_periods: float,
           resample_hz: float | None, report: list[str]) -> tuple[np.ndarray, list[np.ndarray]]:
    """The log's timestamps and each block's values on them, never interpolated across a gap of any file.

    The time base is the first accelerometer's rows (or, with ``resample_hz``, a uniform grid), over the
    span all files share; its times strictly inside a gap of a file whose columns are interpolated (a step
    over ``max_gap_periods`` of that file's nominal period) are left out, and the report says where.
    """
    def name(key: tuple) -> str:
        same_file = sum(1 for k in groups if k[0] == key[0]) > 1
        return str(key[0]) + (f" (time column {key[1]!r})" if same_file else "")

    grid, in_span, interpolated = _time_base(groups, base_key, resample_hz, name, report)
    gaps = {k: find_gaps(groups[k][0], max_gap_periods) for k in groups}
    keep, found = _gaps_left_out(grid, groups, tables, gaps, interpolated, name)
    _report_gaps(found, int(grid[0]) if grid.size else 0, max_gap_periods, resample_hz is not None or len(groups) > 1,
                 report)
    t_out = grid[keep]
    if resample_hz is None:
        _report_base_timing(t_out, gaps[base_key], base_key, len(found), max_gap_periods, report)
    columns = []
    for key, values in blocks:
        if key == base_key and resample_hz is None:
            columns.append(values[in_span][keep])
        else:
            columns.append(interpolate(groups[key][0], values, t_out))
    return t_out, columns


def _time_base(groups: dict, base_key: tuple, resample_hz: float | None, name, report: list[str]):
    """(the time base over the span all files share, which rows of the base file are in that span (None with
    ``resample_hz``), the keys of the files interpolated onto it); the report says how it was made."""
    lo = max(int(g[0][0]) for g in groups.values())
    hi = min(int(g[0][-1]) for g in groups.values())
    t_base = groups[base_key][0]
    in_span = None
    if resample_hz is None:
        in_span = (t_base >= lo) & (t_base <= hi)
        grid = t_base[in_span]
        interpolated = [k for k in groups if k != base_key]
    else:
        period = max(1, int(round(1e9 / resample_hz)))
        grid = uniform_grid(lo, hi, period) if hi >= lo else np.zeros(0, dtype=np.int64)
        interpolated = list(groups)
    if len(groups) > 1 and grid.size < 2:
        raise LogFormatError(f"the files {', '.join(str(k[0]) for k in groups)} share no common time span "
                             "(are their times in the same clock and unit?)", base_key[0])
    if resample_hz is not None:
        report.append(f"resampled: {', '.join(name(k) for k in groups)} linearly interpolated onto a uniform grid "
                      f"at {resample_hz:g} Hz (every {period} ns) over the span all files share "
                      f"({(hi - lo) * 1e-9:.3f} s)")
    elif len(groups) > 1:
        report.append(f"aligned: {', '.join(name(k) for k in interpolated)} linearly interpolated onto the "
                      f"timestamps of {base_key[0]}; {int(np.count_nonzero(~in_span))} row(s) of {base_key[0]} "
                      "outside the span all files share left out")
    return grid, in_span, interpolated


def _gaps_left_out(grid: np.ndarray, groups: dict, tables: dict, gaps: dict, interpolated: list, name):
    """(which times of ``grid`` to keep, the gaps that left some out: (start, end, file, its two lines, the
    file's period, rows left out) each, in time order): the times strictly inside a gap of an interpolated file."""
    keep = np.ones(grid.size, dtype=bool)
    found = []
    for k in interpolated:
        g = gaps[k]
        t = groups[k][0]
        for a, b in zip(g.start_ns.tolist(), g.end_ns.tolist()):
            inside = (grid > a) & (grid < b)
            n = int(np.count_nonzero(inside & keep))
            if inside.any():
                keep &= ~inside
                i = int(np.searchsorted(t, a))
                lines = (tables[k].lines[i], tables[k].lines[i + 1])
                found.append((a, b, name(k), lines, g.period_ns, n))
    found.sort()
    return keep, found


def _report_gaps(found: list, t0: int, max_gap_periods: float, interpolating: bool, report: list[str]) -> None:
    """The gaps of the interpolated files in the report: the first :data:`MAX_SHOWN_GAPS` one by one (times
    from ``t0``), the others counted; or that there is none (when a file is ``interpolating``)."""
    for a, b, where, (la, lb), p, n in found[:MAX_SHOWN_GAPS]:
        report.append(f"gap: {where} has no row from {(a - t0) * 1e-9:.3f} s to {(b - t0) * 1e-9:.3f} s of the log "
                      f"(lines {la} to {lb}, a step of {(b - a) * 1e-9:.3f} s, over {max_gap_periods:g} of its "
                      f"{p * 1e-6:.4g} ms periods): {n} row(s) of the time base in it left out, not interpolated")
    if len(found) > MAX_SHOWN_GAPS:
        rest = found[MAX_SHOWN_GAPS:]
        report.append(f"gap: {len(rest)} more, {sum(f[5] for f in rest)} row(s) of the time base left out in them")
    if found:
        report.append(f"gaps: {len(found)} step(s) over {max_gap_periods:g} periods in the interpolated files, "
                      f"{sum(f[5] for f in found)} row(s) of the time base left out; the log has a time gap at each")
    elif interpolating:
        report.append(f"gaps: no step over {max_gap_periods:g} periods in the interpolated files")


def _report_base_timing(t_out: np.ndarray, g, base_key: tuple, found: int, max_gap_periods: float,
                        report: list[str]) -> None:
    """Without resampling: the gaps ``g`` of the time base's own file kept as time gaps of the log, and the steps
    of ``t_out`` readers will take for breaks beyond those gaps (and the ``found`` ones of the other files)."""
    if len(g):
        # only those whose two rows are both in the written log (the others lie in rows left out)
        step = np.searchsorted(t_out, g.start_ns)
        inside = step < t_out.size - 1
        inside[inside] &= (t_out[step[inside]] == g.start_ns[inside]) & (t_out[step[inside] + 1] == g.end_ns[inside])
        kept = int(np.count_nonzero(inside))
        report.append(f"gaps of the time base {base_key[0]}: {kept} step(s) over {max_gap_periods:g} of its "
                      f"{g.period_ns * 1e-6:.4g} ms periods, kept as time gaps of the log"
                      + (f" ({len(g) - kept} more in rows left out)" if kept < len(g) else ""))
    if t_out.size > 2:
        dt = np.diff(t_out)
        breaks = int(np.count_nonzero(dt > GAP_FACTOR * float(np.median(dt))))
        if breaks > found + len(g):
            rate = nominal_rate_hz(t_out)
            report.append(f"timing: {breaks} step(s) of the log's timestamps exceed {GAP_FACTOR:g} of their median "
                          f"{float(np.median(dt)) * 1e-6:.4g} ms (jitter of {base_key[0]}'s times); readers of the "
                          f"log treat each as a break, where estimators restart: --resample-hz {rate:.4g} puts the "
                          "log on a uniform grid")

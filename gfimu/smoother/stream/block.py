"""The fixed-lag smoother's steady state over a block of samples in one compiled call.

Pushed sample by sample (:meth:`FixedLagSmoother.push <gfimu.smoother.stream.fixed_lag.FixedLagSmoother.push>`),
the window filter's update is one compiled call (:func:`~gfimu.smoother.stream.kernels.advance_update`), but
the rest of a sample's work is Python: the clock, the history and the local motion density the model is
chosen on, the step's process noise, the sign chain, the branch decision's test of the oldest step, reading
the oldest state and dropping it; about as much time again as the update. :func:`advance_block` does all of
that for a run of samples in one call, with the same compiled functions the per-sample path calls
(:mod:`gfimu.smoother.stream.kernels`), so the states are the same to the last bit
(``tests/test_stream_block.py``). It stops at the first sample where the stream has more to do than that:

- before a sample (:data:`BEFORE`), nothing of it taken: a gap, time not going forward, a non-finite reading,
  a model choice about to be put in use, an array to grow (the window's, the epochs', the local density's
  ring), a sign chain not started;
- within a sample, what it did kept: the model choice's decision (:data:`OBSERVED`: a choice due or the motion
  outgrowing the model with none pending, or the once-a-second look for a slow turn; made before the sample's
  update, :meth:`~gfimu.smoother.stream.fixed_lag.FixedLagSmoother._observe_decide`), the sign chain moving a
  run of states onto another branch (:data:`MOVE`, after the update), the update failed (:data:`FAIL`), the
  oldest step outlying, the branch decision to be made (:data:`SETTLE`, while the states due are given out).

The per-sample code takes the sample there and the block goes on after it: a steady stream is a call per few
hundred samples (the start of a segment, its first model's stretch and its held rows, goes sample by sample).

:func:`run` is the Python side: whether the block applies (:func:`ready`), the step table, the call, the
stream's Python state brought up to date from it, and the stop handed back to the per-sample code.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .model_choice import OUTGROWN_FACTOR, RESOLVED_FACTOR
from .states import StateRows
from .kernels import (EP_COUNT, EP_FIRST, EP_HEAD, EP_N, CH_HAS, advance_update, chain_push, epochs_bring_up,
                      epochs_close, flush_lazy, lazy_mean, local_density_push, move_to_start, reset_factors,
                      scaled_process_noise, window_step_residual2)

DONE, BEFORE, OBSERVED, MOVE, FAIL, SETTLE = 0, 1, 2, 3, 4, 5
"""How a block ended (module docstring)."""

# the block's own state, in and out (``iv``: int64, ``fv``: float64)
IV_CLOCK, IV_K, IV_ACCEPTED, IV_TOTAL, IV_LO, IV_HI, IV_SPLIT, IV_BASE, IV_UPDATES, IV_OUT, IV_STOP, IV_CODE, \
    IV_STEP, IV_ADDED, IV_WHY = range(15)
WHY_TIME, WHY_READING, WHY_CHOICE_IN_USE, WHY_ROOM, WHY_CHAIN, WHY_EPOCHS, WHY_LOCAL = range(1, 8)
"""Why a block stopped before a sample (``iv[IV_WHY]``): time not going forward or a gap, a reading not finite, a
model choice to put in use, the window outgrowing its arrays, the sign chain not started, the epochs' arrays
full, the local density's ring full."""
FV_JERK, FV_RESOLVED, FV_LOCAL = range(3)
# settings (``ci``: int64, ``cf``: float64)
CI_LAG_NS, CI_SWAP_AT, CI_RETUNE_NS, CI_CHOSEN_AT, CI_TUNE_MIN_N, CI_TURN_AT, CI_PERIOD_NS, CI_LAZY, CI_SETTLE_STATES, \
    CI_CHAIN, CI_OBSERVE, CI_ROBUST, CI_STILL, CI_LOCAL, CI_SETTLE = range(15)
# (CI_SWAP_AT: -1 when no choice is pending)
CF_GAP_NS, CF_VAR, CF_FLOOR2, CF_SLOPE2, CF_Q, CF_OUTGROWN, CF_RESOLVED, CF_C_DW, CF_OUTLYING2, CF_CHAIN_C2, \
    CF_CHAIN_MARGIN = range(11)

_ZERO9 = np.zeros(9)
_NEVER = 1 << 62


@njit(cache=True, nogil=True, inline="always")
def _waits(ep, stale, k):
    count = ep[EP_COUNT]
    if count == 0:
        return False
    head = ep[EP_HEAD]
    return stale[head, 0] <= k < stale[(head + count - 1) % stale.shape[0], 1]


@njit(cache=True, nogil=True)
def _read(s, lo, split, base, lazy_steps, mean, var, cross, u, Ts, us, Ws, ep, stale):
    """The mean of the state in slot ``s`` as :meth:`WindowFilter.mean
    <gfimu.smoother.stream.window_filter.WindowFilter.mean>` reads it (a lazy one brought up to date first where it
    waits for epochs)."""
    if s >= split:
        return mean[s].copy()
    k = base + s
    if _waits(ep, stale, k):
        epochs_bring_up(Ts, us, Ws, ep, stale, k + 1, base + lo, lazy_steps, base, mean, var, cross)
    return lazy_mean(mean[s], cross[s], u)


@njit(cache=True, nogil=True)
def _epoch_room(Ts, ep, stale):
    """Whether :func:`~gfimu.smoother.stream.kernels.epochs_close` would close an epoch without growing an array."""
    count = ep[EP_COUNT]
    if count + 2 > stale.shape[0]:
        return False
    n = ep[EP_N]
    if n < Ts.shape[0]:
        return True
    need = ep[EP_FIRST] + n
    for j in range(count):
        e = stale[(ep[EP_HEAD] + j) % stale.shape[0], 2]
        if e < need:
            need = e
    return need - ep[EP_FIRST] > 0


@njit(cache=True, nogil=True)
def advance_block(times, accel, i0, i1, iv, fv, xn, q_last,
                  step_of, F_tab, Q_tab, M_tab, motion_tab,
                  mean, var, cross, Fs, Qs, has_step, t_slot, P, T, u, W, Ts, us, Ws, ep, stale,
                  R0, S_q, S_dw, S_f, slope, c_robust, loss, iterations, tolerance, branches, normal, prior_margin,
                  c_process, process_loss,
                  h_t, h_accel, h_has_gyro, h_has_row,
                  pinv_dw, ld_dw, ld_t, ld_s, ld_i, ld_f,
                  ch_w, ch_dw, ch_cost, ch_backs, ch_ks, ch_st, ch_out, ch_normal,
                  ci, cf, out_t, out_x):
    """Samples ``i0 … i1 - 1`` of ``times`` (n,) and ``accel`` (n, axes) through the stream (module docstring),
    in place on its arrays: the window's (``mean`` … ``stale``, :mod:`gfimu.smoother.stream.window_filter`), the
    history's (``h_*``), the local density's (``ld_*``), the sign chain's (``ch_*``), ``iv`` and ``fv`` (the
    clock, the indices, the counts; the jerk factor), ``xn`` (the newest state's mean), ``q_last`` (the newest
    step's process noise). ``step_of[i - i0]``: sample i's row of the step table (``F_tab``, ``Q_tab`` of the unit
    step, ``M_tab`` and ``motion_tab`` to scale its process noise). The states given out are written to
    ``out_t``, ``out_x`` (``iv[IV_OUT]`` of them); ``iv[IV_STOP]`` and ``iv[IV_CODE]`` say where and how the block
    ended, ``iv[IV_ADDED]`` how many samples went into the window whole."""
    base = iv[IV_BASE]
    cap = mean.shape[0]
    lazy_steps = ci[CI_LAZY]
    hcap = h_t.shape[0]
    n_out = iv[IV_OUT]
    scale = np.empty(9)
    y = np.empty(accel.shape[1])
    for i in range(i0, i1):
        t = times[i]
        for a in range(y.shape[0]):
            y[a] = accel[i, a]
        iv[IV_STOP] = i
        iv[IV_OUT] = n_out
        # --- before the sample: does the stream have more to do than the block does?
        dt = t - iv[IV_CLOCK]
        if dt <= 0 or dt > cf[CF_GAP_NS]:
            iv[IV_CODE], iv[IV_WHY] = BEFORE, WHY_TIME
            return
        finite = True
        for a in range(y.shape[0]):
            if not np.isfinite(y[a]):
                finite = False
        if not finite:
            iv[IV_CODE], iv[IV_WHY] = BEFORE, WHY_READING
            return
        if ci[CI_SWAP_AT] >= 0 and iv[IV_ACCEPTED] + 1 >= ci[CI_SWAP_AT]:
            iv[IV_CODE], iv[IV_WHY] = BEFORE, WHY_CHOICE_IN_USE
            return
        lo, hi, split = iv[IV_LO], iv[IV_HI], iv[IV_SPLIT]
        if hi >= cap:  # the window's states moved to the arrays' start (WindowFilter._make_room)
            if hi - lo >= cap // 2:  # (grown, by the per-sample code)
                iv[IV_CODE], iv[IV_WHY] = BEFORE, WHY_ROOM
                return
            flush_lazy(lo, split, base, lazy_steps, mean, var, cross, T, u, W, Ts, us, Ws, ep, stale)
            move_to_start(lo, hi, mean, var, cross, Fs, Qs, has_step, t_slot)
            base += lo
            hi -= lo
            lo = 0
            split = hi
            iv[IV_LO], iv[IV_HI], iv[IV_SPLIT], iv[IV_BASE] = lo, hi, split, base
        if ci[CI_CHAIN] and not ch_st[CH_HAS]:
            iv[IV_CODE], iv[IV_WHY] = BEFORE, WHY_CHAIN
            return
        if hi + 1 - split >= lazy_steps and split > lo and not _epoch_room(Ts, ep, stale):
            iv[IV_CODE], iv[IV_WHY] = BEFORE, WHY_EPOCHS
            return
        observe = ci[CI_OBSERVE] != 0
        if observe and ci[CI_LOCAL] and ld_i[2] and ld_i[1] == ld_t.shape[0]:
            iv[IV_CODE], iv[IV_WHY] = BEFORE, WHY_LOCAL
            return
        # --- the sample is taken (FixedLagSmoother.push, then _observe)
        iv[IV_CLOCK] = t
        iv[IV_ACCEPTED] += 1
        if observe:
            slot = iv[IV_TOTAL] % hcap
            h_t[slot] = t
            for a in range(y.shape[0]):
                h_accel[slot, a] = y[a]
            h_has_gyro[slot] = False
            h_has_row[slot] = False
            iv[IV_TOTAL] += 1
            robust = ci[CI_ROBUST] != 0
            if robust:
                w2 = xn[0] * xn[0] + xn[1] * xn[1] + xn[2] * xn[2]
                noise_var = cf[CF_FLOOR2] + cf[CF_SLOPE2] * w2
            else:
                noise_var = cf[CF_VAR]
            local = -1.0
            if ci[CI_LOCAL]:
                density, resolved, room = local_density_push(t, y, noise_var, pinv_dw, cf[CF_C_DW], ld_dw, ld_t, ld_s,
                                                             ld_i, ld_f, ci[CI_PERIOD_NS], cf[CF_RESOLVED])
                if density >= 0.0:
                    fv[FV_RESOLVED] = 1.0 if resolved else 0.0
                    local = density
            jerk = 1.0
            if local >= 0.0 and robust:
                r = local / cf[CF_Q]
                jerk = r if r < 1.0 else 1.0
            fv[FV_JERK] = jerk
            fv[FV_LOCAL] = local
            # the decision (FixedLagSmoother._observe_decide) left to the per-sample code where it does anything:
            # a choice when none is pending (due, or the motion outgrew the model), the look for a slow turn
            if min(iv[IV_TOTAL], hcap) >= ci[CI_TUNE_MIN_N]:
                due = t - ci[CI_CHOSEN_AT] >= ci[CI_RETUNE_NS]
                outgrown = (local >= 0.0 and fv[FV_RESOLVED] != 0.0 and local > cf[CF_OUTGROWN] * cf[CF_Q]
                            and t - ci[CI_CHOSEN_AT] >= 1_000_000_000)
                if ((ci[CI_SWAP_AT] < 0 and (due or outgrown))
                        or (not (due or outgrown) and ci[CI_STILL] and t - ci[CI_TURN_AT] >= 1_000_000_000)):
                    iv[IV_CODE] = OBSERVED
                    return
        # --- the update (_add_sample: the step, the window filter's advance)
        k = iv[IV_K] + 1
        row = step_of[i - i0]
        F = F_tab[row]
        jerk = fv[FV_JERK]
        if jerk == 1.0:
            Q = Q_tab[row]
        else:
            for a in range(9):
                scale[a] = jerk * jerk if motion_tab[row, a] else 1.0
            Q = scaled_process_noise(M_tab[row], scale)
        for a in range(9):
            for b in range(9):
                q_last[a, b] = Q[a, b]
        iv[IV_STEP] = row
        split_new, ok = advance_update(F, Q, _ZERO9, P, T, u, W, mean, var, cross, lo, split, hi, _NEVER, y, R0, S_q,
                                       S_dw, S_f, slope, c_robust, loss, iterations, tolerance, branches, normal,
                                       prior_margin, c_process, process_loss)
        hi += 1
        iv[IV_HI] = hi
        if not ok:
            iv[IV_CODE] = FAIL
            return
        split = split_new
        iv[IV_UPDATES] += 1
        if hi - split >= lazy_steps:  # the end of an epoch (WindowFilter._boundary)
            if split > lo:
                epochs_close(Ts, us, Ws, ep, stale, T, u, W, base + lo, base + split)
            reset_factors(T, u, W)
            split = hi
        iv[IV_SPLIT] = split
        s = k - base
        for a in range(9):
            for b in range(9):
                Fs[s, a, b] = F[a, b]
                Qs[s, a, b] = Q[a, b]
        has_step[s] = True
        t_slot[s] = t
        iv[IV_K] = k
        # --- the sign chain on the newest state (_follow_sign)
        x = _read(s, lo, split, base, lazy_steps, mean, var, cross, u, Ts, us, Ws, ep, stale)
        for a in range(9):
            xn[a] = x[a]
        if ci[CI_CHAIN]:
            oldest = base + lo if lo < hi - 1 else k
            if chain_push(k, t, xn[0:3], xn[3:6], cf[CF_CHAIN_C2], oldest, cf[CF_CHAIN_MARGIN], ch_normal, ch_w,
                          ch_dw, ch_cost, ch_backs, ch_ks, ch_st, ch_out):
                iv[IV_CODE] = MOVE
                return
        iv[IV_ADDED] += 1
        # --- the states due (_emit_due): the branch decision's test of the oldest step, the oldest read, dropped
        cutoff = t - ci[CI_LAG_NS] + 1000
        while hi - lo > 1 and t_slot[lo] <= cutoff:
            if ci[CI_SETTLE] and min(hi, lo + 1 + ci[CI_SETTLE_STATES]) - lo >= 3 and has_step[lo + 1]:
                k0 = base + lo
                epochs_bring_up(Ts, us, Ws, ep, stale, k0 + 2, base + lo, lazy_steps, base, mean, var, cross)
                e2 = window_step_residual2(Fs[lo + 1], Qs[lo + 1], mean, cross, u, split, lo)
                if e2 >= 0.0 and e2 > cf[CF_OUTLYING2]:
                    iv[IV_LO], iv[IV_SPLIT], iv[IV_OUT] = lo, split, n_out
                    iv[IV_CODE] = SETTLE
                    return
            x = _read(lo, lo, split, base, lazy_steps, mean, var, cross, u, Ts, us, Ws, ep, stale)
            out_t[n_out] = t_slot[lo]
            for a in range(9):
                out_x[n_out, a] = x[a]
            n_out += 1
            lo += 1
            if split < lo:
                split = lo
            while ep[EP_COUNT] > 0 and stale[ep[EP_HEAD], 1] <= base + lo:  # (Epochs.forget_before)
                ep[EP_HEAD] = (ep[EP_HEAD] + 1) % stale.shape[0]
                ep[EP_COUNT] -= 1
        iv[IV_LO], iv[IV_SPLIT] = lo, split
    iv[IV_STOP] = i1
    iv[IV_OUT] = n_out
    iv[IV_CODE] = DONE


# --- the Python side ------------------------------------------------------------------------------------------

_EMPTY9 = np.zeros((1, 9))  # (the local density's inversion rows where it has none)


def ready(sm) -> bool:
    """Whether the smoother ``sm`` (:class:`~gfimu.smoother.stream.fixed_lag.FixedLagSmoother`) is in the state
    :func:`advance_block` goes on from: a segment under way in the compiled window filter (its start decided,
    its first model chosen), no σ given out, no factor groups, and its Python state in step with the window's."""
    from .window_filter import WindowFilter

    seg, choice = sm._segment, sm._choice
    engine = seg.engine
    if (sm.closed or sm._sigma is not None or sm.config.compute_sigma or not isinstance(engine, WindowFilter)
            or not (engine.compiled and engine.deferred) or choice.first_pending or sm._hold.deciding
            or sm._hold.held or seg.warmup or seg.prev_x is None or seg.prev_sample is None
            or sm._clock.last_ns is None):
        return False
    sets = sm.model.factor_sets
    if sets.other_steps or sets.per_sample:
        return False
    store = engine._store
    return (bool(seg.window) and len(seg.window) == store.hi - store.lo and seg.window[0][0] == store.base + store.lo
            and seg.k == store.base + store.hi - 1)


def run(sm, times_ns: np.ndarray, accel: np.ndarray, i0: int, i1: int) -> tuple[int, list]:
    """Samples ``i0 …`` (before ``i1``) of ``times_ns`` (n,) int64 and ``accel`` (n, axes) float64 into the
    smoother ``sm`` (which :func:`ready` accepts): as many as one :func:`advance_block` call takes, then the
    sample it stopped at by the per-sample code. Returns (the next sample's index, the states given out: a
    :class:`StateRows` and the per-sample code's :class:`~gfimu.smoother.stream.fixed_lag.StateEstimate`
    objects, oldest first)."""
    from .window_filter import OUTLYING_STEP2, SETTLE_STATES, FilterFailure

    seg, choice, clock = sm._segment, sm._choice, sm._clock
    engine = seg.engine
    store, lazy, newest = engine._store, engine._lazy, engine._newest
    epochs = lazy.epochs
    model, rules, chosen = sm.model, choice.rules, choice.stream_model
    # the step into each sample, from the one before (the first from the newest sample taken)
    dt = np.diff(times_ns[i0:i1], prepend=np.int64(seg.prev_sample[0]))
    keys, step_of = np.unique(dt, return_inverse=True)
    n_steps = len(keys)
    F_tab, Q_tab, M_tab = np.zeros((n_steps, 9, 9)), np.zeros((n_steps, 9, 9)), np.zeros((n_steps, 9, 9))
    motion_tab = np.zeros((n_steps, 9), dtype=bool)
    gap_ns = sm.config.gap_ns
    for j, key in enumerate(keys.tolist()):
        if 0 < key <= gap_ns:  # (the others stop the block before their sample)
            parts = model.step_parts(key * 1e-9)
            if parts is None:
                return _one(sm, times_ns, accel, i0)
            F_tab[j], Q_tab[j], M_tab[j], motion_tab[j] = parts
    observe = bool((rules.auto or rules.tune) and chosen is not None)
    robust = bool(observe and chosen.robust)
    still = bool(observe and not chosen.moving and chosen.tuning is None and not robust)
    check = chosen.check if robust else None
    local = choice.local
    chain = sm.stream_model is not None and sm.stream_model.sign_scale_radps is not None
    scale = float(sm.stream_model.sign_scale_radps) if chain else 0.0
    pending = choice.pending
    ci = np.array([sm.config.lag_ns, -1 if pending is None else pending.swap_at, rules.retune_ns,
                   chosen.chosen_at_ns if chosen is not None else 0, rules.tune_min_n, choice.turn_checked_ns,
                   local._period_ns, engine.lazy_steps, SETTLE_STATES, chain, observe, robust, still,
                   bool(local.available), bool(engine._branches and not engine._record.unsettled)], dtype=np.int64)
    cf = np.array([gap_ns, choice.model.noise.mean_accel_var_mps2 if observe and not robust else 0.0,
                   check.noise_floor_mps2 ** 2 if robust else 0.0, check.noise_slope_mps2_per_radps ** 2 if robust else 0.0,
                   chosen.groups.model.omega_dot_random_walk_radps2_per_sqrt_s if chosen is not None else 1.0,
                   OUTGROWN_FACTOR, RESOLVED_FACTOR, local._c_dw if local.available else 0.0, OUTLYING_STEP2,
                   scale * scale, sm._signs.margin])
    iv = np.array([clock.last_ns, seg.k, choice.accepted, choice.history.total, store.lo, store.hi, store.split,
                   store.base, engine._counts.updates, 0, i0, 0, -1, 0, 0], dtype=np.int64)
    fv = np.array([choice.jerk_factor, 1.0 if local.resolved else 0.0, -1.0])
    xn = np.array(seg.prev_x, dtype=float)
    q_last = np.zeros((9, 9))
    n_max = (i1 - i0) + (store.hi - store.lo) + 1
    out_t, out_x = np.zeros(n_max, dtype=np.int64), np.zeros((n_max, 9))
    history, signs = choice.history, sm._signs
    k_first = seg.k + 1
    advance_block(times_ns, accel, i0, i1, iv, fv, xn, q_last, step_of.astype(np.int64), F_tab, Q_tab, M_tab, motion_tab,
                  store.mean, store.var, store.cross, store.F, store.Q, store.has_step, store.t_ns, newest.P, lazy.T,
                  lazy.u, lazy.W, epochs.T, epochs.u, epochs.W, epochs.ep, epochs.stale, *engine._ops.kernel_model,
                  *engine._ops.kernel_options, history.times_ns, history.accel, history.has_gyro, history.has_row,
                  local._pinv_dw if local.available else _EMPTY9, local._dw, local._t, local._s, local._i, local._f,
                  signs._w, signs._dw, signs._cost, signs._backs, signs._ks, signs._st, signs._out, signs.normal,
                  ci, cf, out_t, out_x)
    code, stop, n_out, added = int(iv[IV_CODE]), int(iv[IV_STOP]), int(iv[IV_OUT]), int(iv[IV_ADDED])
    # the Python state brought up to date
    clock.last_ns, seg.k, choice.accepted, history.total = int(iv[IV_CLOCK]), int(iv[IV_K]), int(iv[IV_ACCEPTED]), \
        int(iv[IV_TOTAL])
    store.lo, store.hi, store.split, store.base = int(iv[IV_LO]), int(iv[IV_HI]), int(iv[IV_SPLIT]), int(iv[IV_BASE])
    engine._counts.updates = int(iv[IV_UPDATES])
    choice.jerk_factor = float(fv[FV_JERK])
    local.resolved = bool(fv[FV_RESOLVED])
    if iv[IV_STEP] >= 0:  # the newest step taken
        newest.F, newest.Q = F_tab[int(iv[IV_STEP])].copy(), q_last
    window, raw = seg.window, seg.raw
    for j in range(added):
        t = int(times_ns[i0 + j])
        window.append((k_first + j, t))
        raw.append((t, accel[i0 + j], None))
    for _ in range(n_out):
        window.popleft()
        raw.popleft()
    if added and code != MOVE:  # (after a move the per-sample code keeps the newest state, below)
        seg.prev, seg.prev_x, seg.prev_sample = (raw[-1][0], xn[0:3], xn[3:6], xn[6:9]), xn, raw[-1]
    items: list = [StateRows(out_t[:n_out], out_x[:n_out])] if n_out else []
    if code == DONE:
        return i1, items
    i = stop
    sample = (int(times_ns[i]), accel[i], None)
    if code == BEFORE:  # the sample by the per-sample code, whole
        return i + 1, items + list(sm.push(*sample[:2]).smoothed)
    if code == OBSERVED:  # the decision on a model choice, then the sample's update (FixedLagSmoother._observe)
        sm._observe_decide(sample[0], None if fv[FV_LOCAL] < 0 else float(fv[FV_LOCAL]))
        sm._add_sample(sample)
    elif code == MOVE:  # the run the sign chain moves (FixedLagSmoother._follow_sign), then the sample kept
        engine.move_branch(int(signs._out[0]), int(signs._out[1]))
        x = engine.mean(seg.k)
        window.append((seg.k, sample[0]))
        raw.append(sample)
        sm._remember_newest(x)
    elif code == FAIL:  # the update failed (FixedLagSmoother._add_sample)
        sm._recover(sample, sm._failure(sample[0], FilterFailure(
            "singular innovation covariance or non-finite values in the update")))
    return i + 1, items + list(sm._scaled(sm._emit_due()))


def _one(sm, times_ns, accel, i):
    """Sample ``i`` by the per-sample code: (the next index, its states)."""
    return i + 1, list(sm.push(int(times_ns[i]), accel[i]).smoothed)

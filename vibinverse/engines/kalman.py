"""The state-space engine: one Kalman recursion for every model composed of terms
(`vibinverse.terms`), whose transition and process noise are block diagonal.

    x_k = Phi_k x_{k-1} + w_k,  w_k ~ N(0, Q_k);   y_k = m_k h_s . x_k + h_n . x_k + v_k,  v_k ~ N(0, r)

Phi_k = phis[idx[k]] and Q_k = qs[idx[k]] (one table per distinct time step: a uniform grid has
one, irregular stamps a few); each state i belongs to the block lo[i]..hi[i] (1 x 1 or 2 x 2: an
oscillator, a walk, an integrated walk, an Ornstein-Uhlenbeck state). NaN samples are gaps: the
update is skipped and the likelihood is that of the observed samples. `m_k` (`hm`, optional) is a
multiplicative gain drift on the first `nscaled` states (the signal terms). The covariance is
propagated block pair by block pair in closed form (`predict_block_covariance`, O(n^2) a step
instead of O(n^3)), and once the Riccati recursion has reached its fixed point the gain is held
until a gap or another step (`is_calm`): O(n) a step from there, the same numbers
to rounding. `block_filter` is the recursion, `propagate_blocks` draws the process at the same
steps, `run_blocks` is the Python entry.
"""

from __future__ import annotations

import math
import os

import numpy as np

try:
    import numba
    from numba import njit
except ImportError:  # pragma: no cover - numba is a dependency; this keeps the module importable

    def njit(*args, **kwargs):
        return (lambda f: f) if not (args and callable(args[0])) else args[0]
else:
    if not numba.config.CACHE_DIR:  # NUMBA_CACHE_DIR unset: compiled kernels go to the user's cache,
        # never into the installed package (a later editable install would leave them as a shadow package)
        numba.config.CACHE_DIR = os.path.join(
            os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "vibinverse", "numba"
        )


_LOG_2PI = math.log(2.0 * math.pi)

FREEZE_TOL = 1e-14  # the filter holds its gain once the covariance has converged to this (relative)
FREEZE_ROUNDING = 1e-15  # a relative change this small is rounding: it counts as converged


@njit(cache=True, fastmath=False, nogil=True)
def gain_change(ph, s, prev_gain, prev_s):  # pragma: no cover - compiled; tested through the filter
    """The relative change of the Kalman gain ph / s and the innovation variance s since the last
    observed sample (prev_gain, prev_s): the largest change of a gain entry over the largest gain,
    and of s over s."""
    n = ph.shape[0]
    scale = 0.0
    for i in range(n):
        scale = max(scale, abs(ph[i] / s))
    delta = abs(s - prev_s) / s
    for i in range(n):
        d = abs(ph[i] / s - prev_gain[i])
        if d > 0.0:  # a gain that fell to 0 (a free decay's covariance underflowed) is a change
            delta = max(delta, d / scale) if scale > 0.0 else math.inf
    return delta


@njit(cache=True, fastmath=False, nogil=True)
def is_calm(delta, last_delta):  # pragma: no cover - compiled; tested through the filter
    """Whether a change `delta` after `last_delta` means the recursion has converged: at rounding,
    or shrinking geometrically with what remains of it (delta^2 / (last - delta), the tail of the
    geometric series) below FREEZE_TOL."""
    return delta <= FREEZE_ROUNDING or (
        delta < last_delta < np.inf and delta * delta <= FREEZE_TOL * (last_delta - delta)
    )


@njit(cache=True, fastmath=False, nogil=True)
def held_update(x, h, gain, yk):  # pragma: no cover - compiled; tested through the filters
    """A step with the held gain: the innovation v = yk - h . x, and x += gain v in place; returns v."""
    v = yk
    for i in range(x.shape[0]):
        v -= h[i] * x[i]
    for i in range(x.shape[0]):
        x[i] += gain[i] * v
    return v


@njit(cache=True, fastmath=False, nogil=True)
def predict_block_covariance(p, phi, q, bs, bz):  # pragma: no cover - compiled
    """P <- Phi P Phi^T + Q in place, Phi and Q block diagonal (block b: states bs[b] .. bs[b] +
    bz[b] - 1), block pair by block pair in closed form (the upper triangle, mirrored) when every
    block has one or two states; with a larger block, the whole product (symmetrized)."""
    nb = bs.shape[0]
    dense = False
    for a in range(nb):
        dense = dense or bz[a] > 2
    if dense:  # a block of more than two states: the whole covariance, O(n^3)
        n = p.shape[0]
        tmp = np.empty((n, n))
        for i in range(n):
            for j in range(n):
                acc = 0.0
                for m in range(n):
                    acc += phi[i, m] * p[m, j]
                tmp[i, j] = acc
        for i in range(n):
            for j in range(i, n):
                acc = 0.0
                for m in range(n):
                    acc += tmp[i, m] * phi[j, m]
                acc2 = 0.0
                for m in range(n):
                    acc2 += tmp[j, m] * phi[i, m]
                v = 0.5 * ((acc + q[i, j]) + (acc2 + q[j, i]))
                p[i, j] = v
                p[j, i] = v
        return
    for a in range(nb):
        oa = bs[a]
        a00 = phi[oa, oa]
        if bz[a] == 2:
            a01, a10, a11 = phi[oa, oa + 1], phi[oa + 1, oa], phi[oa + 1, oa + 1]
        else:
            a01 = a10 = a11 = 0.0
        for b in range(a, nb):
            ob = bs[b]
            b00 = phi[ob, ob]
            if bz[a] == 2 and bz[b] == 2:
                b01, b10, b11 = phi[ob, ob + 1], phi[ob + 1, ob], phi[ob + 1, ob + 1]
                p00, p01, p10, p11 = p[oa, ob], p[oa, ob + 1], p[oa + 1, ob], p[oa + 1, ob + 1]
                t00 = a00 * p00 + a01 * p10
                t01 = a00 * p01 + a01 * p11
                t10 = a10 * p00 + a11 * p10
                t11 = a10 * p01 + a11 * p11
                m00 = t00 * b00 + t01 * b01
                m01 = t00 * b10 + t01 * b11
                m10 = t10 * b00 + t11 * b01
                m11 = t10 * b10 + t11 * b11
                if a == b:
                    m00 += q[oa, oa]
                    m01 += q[oa, oa + 1]
                    m11 += q[oa + 1, oa + 1]
                    m10 = m01
                p[oa, ob] = m00
                p[oa, ob + 1] = m01
                p[oa + 1, ob] = m10
                p[oa + 1, ob + 1] = m11
                p[ob, oa] = m00
                p[ob + 1, oa] = m01
                p[ob, oa + 1] = m10
                p[ob + 1, oa + 1] = m11
            elif bz[a] == 2:  # b is 1 x 1
                m0 = (a00 * p[oa, ob] + a01 * p[oa + 1, ob]) * b00
                m1 = (a10 * p[oa, ob] + a11 * p[oa + 1, ob]) * b00
                p[oa, ob] = m0
                p[oa + 1, ob] = m1
                p[ob, oa] = m0
                p[ob, oa + 1] = m1
            elif bz[b] == 2:  # a is 1 x 1
                b01, b10, b11 = phi[ob, ob + 1], phi[ob + 1, ob], phi[ob + 1, ob + 1]
                m0 = a00 * (p[oa, ob] * b00 + p[oa, ob + 1] * b01)
                m1 = a00 * (p[oa, ob] * b10 + p[oa, ob + 1] * b11)
                p[oa, ob] = m0
                p[oa, ob + 1] = m1
                p[ob, oa] = m0
                p[ob + 1, oa] = m1
            else:
                m = a00 * p[oa, ob] * b00
                if a == b:
                    m += q[oa, oa]
                p[oa, ob] = m
                p[ob, oa] = m


@njit(cache=True, fastmath=False, nogil=True)
def innovation_density(s, v):  # pragma: no cover - compiled
    """log N(v; 0, s): one observed sample's one-step predictive log density."""
    return -0.5 * (math.log(s) + _LOG_2PI + v * v / s)


@njit(cache=True, fastmath=False, nogil=True)
def emit(k, lk, w, lls, white):  # pragma: no cover - compiled
    """Sample k's log density lk and standardized innovation w into `lls` and `white` (when they
    are not empty)."""
    if lls.shape[0]:
        lls[k] = lk
    if white.shape[0]:
        white[k] = w


@njit(cache=True, fastmath=False, nogil=True)
def hold_step(delta, last_delta, calm, freeze):  # pragma: no cover - compiled
    """(calm samples so far, whether to hold the gain now) after a change `delta` (`is_calm`)."""
    calm = calm + 1 if is_calm(delta, last_delta) else 0
    if calm >= freeze:
        return 0, True
    return calm, False


@njit(cache=True, fastmath=False, nogil=True)
def predict_state(x, xp, phis, u, lo, hi):  # pragma: no cover - compiled; tested through the filters
    """x <- Phi x in place, Phi = phis[u] block diagonal (state i's block lo[i]..hi[i]); xp is
    scratch (the table is indexed in place: a view of it per step cost 7 % of the filter)."""
    n = x.shape[0]
    for i in range(n):
        acc = 0.0
        for m in range(lo[i], hi[i]):
            acc += phis[u, i, m] * x[m]
        xp[i] = acc
    for i in range(n):
        x[i] = xp[i]


@njit(cache=True, fastmath=False, nogil=True)
def rank_one_update(x, p, ph, v, s):  # pragma: no cover - compiled; tested through the filters
    """The measurement update given ph = P h, the innovation v and its variance s: x += ph v / s,
    P -= ph ph^T / s (symmetric), in place."""
    n = x.shape[0]
    for i in range(n):
        x[i] += ph[i] * v / s
    for i in range(n):
        g = ph[i] / s
        for j in range(i, n):
            d = p[i, j] - g * ph[j]
            p[i, j] = d
            p[j, i] = d


@njit(cache=True, fastmath=False, nogil=True)
def block_starts(lo, hi):  # pragma: no cover - compiled
    """(first state, size) of each block of the layout lo, hi."""
    n = lo.shape[0]
    nb = 0
    for i in range(n):
        nb += lo[i] == i
    bs = np.zeros(nb, dtype=np.int64)
    bz = np.zeros(nb, dtype=np.int64)
    b = 0
    for i in range(n):
        if lo[i] == i:
            bs[b] = i
            bz[b] = hi[i] - i
            b += 1
    return bs, bz


@njit(cache=True, fastmath=False, nogil=True)
def block_filter(y, phis, qs, idx, lo, hi, h, r, p0, freeze, white, lls, hm, nscaled):  # pragma: no cover - compiled
    """log p(y) of x_k = Phi_k x_{k-1} + w_k, y_k = h . x_k + v_k with block-diagonal Phi_k
    (= phis[idx[k]]; state i's block is lo[i]..hi[i]) and Q_k, x_0 ~ N(0, P0); NaN gaps skipped.
    Writes the standardized innovations to `white` and each sample's log density to `lls` when
    they are not empty (NaN at gaps). With `freeze` = m > 0, the gain and the innovation variance
    are held once they have stopped changing over m consecutive observed samples of the same step
    (`is_calm`: each change, extrapolated geometrically, below FREEZE_TOL of their scale,
    or at rounding: the Riccati recursion's fixed point to rounding), until a gap or another step
    (module docstring).
    m spans the slowest mode's period: with lightly damped modes the recursion converges with
    an oscillation, whose changes dip towards 0 twice a period long before it has converged; a
    test on one pair of samples then held a gain 0.003 off in log-likelihood, and the likelihood
    jumped by that much between neighbouring parameter values (a finite-difference Hessian of
    6e7 where the curvature is 60). 0: never held. `hm` (empty, or one value per
    sample): the gain drift, multiplying the observation of states 0..nscaled-1 (the modes) at each
    sample; the gain then changes every sample, so it is never held (`freeze` must be False)."""
    n = phis.shape[1]
    hk = h.copy()
    vary = hm.shape[0] > 0
    bs, bz = block_starts(lo, hi)
    nobs = 0
    for i in range(n):
        nobs += h[i] != 0.0
    seen = np.zeros(nobs, dtype=np.int64)
    b = 0
    for i in range(n):
        if h[i] != 0.0:
            seen[b] = i
            b += 1
    x = np.zeros(n)
    xp = np.zeros(n)
    p = p0.copy()
    pf = np.zeros((n, n))
    ph = np.zeros(n)
    gain = np.zeros(n)
    prev_gain = np.zeros(n)
    prev_s = 0.0
    have_prev = False
    prev_u = -1
    last_delta = np.inf
    frozen = False
    calm = 0  # consecutive samples that met the hold's test
    fu = -1
    sf = 1.0
    log_norm = 0.0
    ll = 0.0
    u = 0
    for k in range(y.shape[0]):
        yk = y[k]
        observed = yk == yk
        if k > 0:
            u = idx[k]
            predict_state(x, xp, phis, u, lo, hi)
            if frozen and (u != fu or not observed):
                frozen = False
                for i in range(n):
                    for j in range(n):
                        p[i, j] = pf[i, j]
                have_prev = False
                last_delta = np.inf
            if frozen:
                v = held_update(x, h, gain, yk)
                lk = log_norm - 0.5 * v * v / sf
                ll += lk
                emit(k, lk, v / math.sqrt(sf) if white.shape[0] else 0.0, lls, white)
                continue
            predict_block_covariance(p, phis[u], qs[u], bs, bz)
        if not observed:
            have_prev = False
            emit(k, np.nan, np.nan, lls, white)
            continue
        if vary:
            for i in range(nscaled):
                hk[i] = h[i] * hm[k]
        s = r
        v = yk
        for i in range(n):
            acc = 0.0
            for jj in range(nobs):
                acc += p[i, seen[jj]] * hk[seen[jj]]
            ph[i] = acc
        for jj in range(nobs):
            s += hk[seen[jj]] * ph[seen[jj]]
            v -= hk[seen[jj]] * x[seen[jj]]
        if not s > 0.0:
            if lls.shape[0]:
                lls[k:] = -np.inf
            return -np.inf
        rank_one_update(x, p, ph, v, s)
        lk = innovation_density(s, v)
        ll += lk
        if lls.shape[0]:
            lls[k] = lk
        if white.shape[0]:
            white[k] = v / math.sqrt(s)
        if freeze:
            if have_prev and u == prev_u:
                delta = gain_change(ph, s, prev_gain, prev_s)
                calm, frozen = hold_step(delta, last_delta, calm, freeze)
                if frozen:
                    fu = u
                    sf = s
                    log_norm = -0.5 * (math.log(s) + _LOG_2PI)
                    for i in range(n):
                        gain[i] = ph[i] / s
                        for j in range(n):
                            pf[i, j] = p[i, j]
                last_delta = delta
            else:
                calm = 0
            for i in range(n):
                prev_gain[i] = ph[i] / s
            prev_s = s
            prev_u = u
            have_prev = True
    return ll


@njit(cache=True, fastmath=False, nogil=True)
def propagate_blocks(phis, roots, idx, lo, hi, x0, z, h, out):  # pragma: no cover - compiled; tested by moments
    """out[k] = h . x_k with x_k = Phi_k x_{k-1} + S_k z_k (S_k S_k^T = Q_k, block diagonal)."""
    n = phis.shape[1]
    x = x0.copy()
    xp = np.zeros(n)
    for k in range(out.shape[0]):
        if k > 0:
            u = idx[k]
            for i in range(n):
                acc = 0.0
                for m in range(lo[i], hi[i]):
                    acc += phis[u, i, m] * x[m] + roots[u, i, m] * z[k, m]
                xp[i] = acc
            for i in range(n):
                x[i] = xp[i]
        acc = 0.0
        for i in range(n):
            acc += h[i] * x[i]
        out[k] = acc


@njit(cache=True, fastmath=False, nogil=True)
def vector_filter(d, phis, qs, idx, lo, hi, h, cov, scale2, p0, white, lls):  # pragma: no cover - compiled
    """log p of vector observations d_t = H x_t + v_t (d: (T, r), NaN = not observed; v ~ N(0, cov
    scale2)), x_t = Phi x_{t-1} + w_t with Phi = phis[idx[t]] block diagonal (state i's block
    lo[i]..hi[i]) and x_0 ~ N(0, P0): per sample, the Cholesky factor L of the observed block of
    cov, the whitened L^-1 d and L^-1 H, r sequential scalar updates (`rank_one_update`, as
    `block_filter`'s) and the Jacobian -log det L. Standardized innovations to `white` (T, r) and
    each sample's log density to `lls` when they are not empty (NaN where not observed)."""
    nt, r = d.shape
    n = p0.shape[0]
    tmp = np.zeros((n, n))
    x = np.zeros(n)
    xp = np.zeros(n)
    p = p0.copy()
    ph = np.zeros(n)
    lc = np.zeros((r, r))
    hw = np.zeros((r, n))
    v = np.zeros(r)
    obs = np.zeros(r, dtype=np.int64)
    prev = -1  # the observed pattern whose factor lc holds: r (all), else recomputed
    logdet = 0.0
    ll = 0.0
    for k in range(nt):
        if k > 0:
            u = idx[k]
            predict_state(x, xp, phis, u, lo, hi)
            for i in range(n):  # tmp = Phi P
                for j in range(n):
                    acc = 0.0
                    for m in range(lo[i], hi[i]):
                        acc += phis[u, i, m] * p[m, j]
                    tmp[i, j] = acc
            for i in range(n):  # P = tmp Phi^T + Q
                for j in range(i, n):
                    acc = qs[u, i, j]
                    for m in range(lo[j], hi[j]):
                        acc += tmp[i, m] * phis[u, j, m]
                    p[i, j] = acc
                    p[j, i] = acc
        m_obs = 0
        for j in range(r):
            if d[k, j] == d[k, j]:
                obs[m_obs] = j
                m_obs += 1
        if m_obs == 0:
            if lls.shape[0]:
                lls[k] = np.nan
            if white.shape[0]:
                for j in range(r):
                    white[k, j] = np.nan
            continue
        if not (m_obs == r and prev == r):  # the Cholesky factor of the observed block, and L^-1 H
            for a in range(m_obs):
                for b in range(a + 1):
                    acc = cov[obs[a], obs[b]] * scale2
                    for c in range(b):
                        acc -= lc[a, c] * lc[b, c]
                    if a == b:
                        if not acc > 0.0:
                            if lls.shape[0]:
                                lls[k:] = -np.inf
                            return -np.inf
                        lc[a, a] = math.sqrt(acc)
                    else:
                        lc[a, b] = acc / lc[b, b]
            logdet = 0.0
            for a in range(m_obs):
                logdet += math.log(lc[a, a])
                for i in range(n):
                    acc = h[obs[a], i]
                    for c in range(a):
                        acc -= lc[a, c] * hw[c, i]
                    hw[a, i] = acc / lc[a, a]
            prev = m_obs if m_obs == r else -1
        for a in range(m_obs):  # the whitened observations
            acc = d[k, obs[a]]
            for c in range(a):
                acc -= lc[a, c] * v[c]
            v[a] = acc / lc[a, a]
        lk = -logdet
        for a in range(m_obs):
            s = 1.0
            e = v[a]
            for i in range(n):
                acc = 0.0
                for j in range(n):
                    acc += p[i, j] * hw[a, j]
                ph[i] = acc
            for i in range(n):
                s += hw[a, i] * ph[i]
                e -= hw[a, i] * x[i]
            if not s > 0.0:
                if lls.shape[0]:
                    lls[k:] = -np.inf
                return -np.inf
            rank_one_update(x, p, ph, e, s)
            lk += -0.5 * (math.log(s) + _LOG_2PI + e * e / s)
            if white.shape[0]:
                white[k, obs[a]] = e / math.sqrt(s)
        if white.shape[0]:
            for j in range(r):
                if d[k, j] != d[k, j]:
                    white[k, j] = np.nan
        ll += lk
        if lls.shape[0]:
            lls[k] = lk
    return ll


@njit(cache=True, fastmath=False, nogil=True)
def filter_two_states(
    y, phis, qs, idx, h, r, p0, white, lls, freeze
):  # pragma: no cover - compiled; checked against `filter_steps` and the reference
    """`filter_steps` for n = 2 states (one oscillator: the frame's tilt, a single resonance), the
    same recursion, gaps, outputs and gain hold, with the state and the covariance's three
    distinct entries in scalars: 2-3x faster than the general loops, whose tiny inner loops keep
    x and P in memory (measured 36 against 90-110 ns a sample, 4000 samples)."""
    uniform = idx.shape[0] == 0
    h0, h1 = h[0], h[1]
    x0 = x1 = 0.0
    p00, p01, p11 = p0[0, 0], 0.5 * (p0[0, 1] + p0[1, 0]), p0[1, 1]
    f00 = f01 = f11 = 0.0  # the covariance at the hold
    g0 = g1 = 0.0  # the held gain
    pg0 = pg1 = 0.0  # the previous sample's gain
    prev_s = 0.0
    have_prev = False
    prev_u = -1
    last_delta = np.inf
    frozen = False
    calm = 0
    fu = -1
    log_norm, inv_sf, inv_root = 0.0, 1.0, 1.0
    ll = 0.0
    u = 0
    a00, a01, a10, a11 = phis[0, 0, 0], phis[0, 0, 1], phis[0, 1, 0], phis[0, 1, 1]
    q00, q01, q11 = qs[0, 0, 0], 0.5 * (qs[0, 0, 1] + qs[0, 1, 0]), qs[0, 1, 1]
    loaded = 0
    for k in range(y.shape[0]):
        yk = y[k]
        observed = yk == yk  # NaN: a gap
        if k > 0:
            if not uniform:
                u = idx[k]
                if u != loaded:
                    a00, a01, a10, a11 = phis[u, 0, 0], phis[u, 0, 1], phis[u, 1, 0], phis[u, 1, 1]
                    q00, q01, q11 = qs[u, 0, 0], 0.5 * (qs[u, 0, 1] + qs[u, 1, 0]), qs[u, 1, 1]
                    loaded = u
            t0 = a00 * x0 + a01 * x1
            x1 = a10 * x0 + a11 * x1
            x0 = t0
            if frozen and (u != fu or not observed):  # the held gain no longer applies
                frozen = False
                p00, p01, p11 = f00, f01, f11
                have_prev = False
                last_delta = np.inf
            if frozen:
                v = yk - h0 * x0 - h1 * x1
                x0 += g0 * v
                x1 += g1 * v
                lk = log_norm - 0.5 * v * v * inv_sf
                ll += lk
                if lls.shape[0]:
                    lls[k] = lk
                if white.shape[0]:
                    white[k] = v * inv_root
                continue
            m00 = a00 * p00 + a01 * p01
            m01 = a00 * p01 + a01 * p11
            m10 = a10 * p00 + a11 * p01
            m11 = a10 * p01 + a11 * p11
            n00 = m00 * a00 + m01 * a01 + q00
            n01 = 0.5 * ((m00 * a10 + m01 * a11) + (m10 * a00 + m11 * a01)) + q01
            n11 = m10 * a10 + m11 * a11 + q11
            p00, p01, p11 = n00, n01, n11
        if not observed:
            have_prev = False
            emit(k, np.nan, np.nan, lls, white)
            continue
        ph0 = p00 * h0 + p01 * h1
        ph1 = p01 * h0 + p11 * h1
        s = r + h0 * ph0 + h1 * ph1
        v = yk - h0 * x0 - h1 * x1
        if not s > 0.0:
            if lls.shape[0]:
                lls[k:] = -np.inf
            return -np.inf
        k0, k1 = ph0 / s, ph1 / s
        x0 += ph0 * v / s
        x1 += ph1 * v / s
        p00 -= ph0 * ph0 / s
        p01 -= ph0 * ph1 / s
        p11 -= ph1 * ph1 / s
        lk = innovation_density(s, v)
        ll += lk
        if lls.shape[0]:
            lls[k] = lk
        if white.shape[0]:
            white[k] = v / math.sqrt(s)
        if freeze:
            if have_prev and u == prev_u:
                scale = max(abs(k0), abs(k1))  # `gain_change`
                delta = abs(s - prev_s) / s
                d0, d1 = abs(k0 - pg0), abs(k1 - pg1)
                if d0 > 0.0:
                    delta = max(delta, d0 / scale) if scale > 0.0 else math.inf
                if d1 > 0.0:
                    delta = max(delta, d1 / scale) if scale > 0.0 else math.inf
                calm, frozen = hold_step(delta, last_delta, calm, freeze)
                if frozen:
                    fu = u
                    log_norm = -0.5 * (math.log(s) + _LOG_2PI)
                    inv_sf = 1.0 / s
                    inv_root = 1.0 / math.sqrt(s)
                    g0, g1 = k0, k1
                    f00, f01, f11 = p00, p01, p11
                last_delta = delta
            else:
                calm = 0
            pg0, pg1 = k0, k1
            prev_s = s
            prev_u = u
            have_prev = True
    return ll


def block_layout(phis: np.ndarray, qs: np.ndarray, p0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi): the finest split of the states into contiguous blocks that no transition, process
    noise or initial covariance entry couples (state i's block is lo[i]..hi[i] - 1); a dense model is
    one block."""
    n = phis.shape[1]
    coupled = (np.abs(phis).max(axis=0) + np.abs(qs).max(axis=0) + np.abs(p0)) != 0.0
    coupled |= coupled.T
    lo, hi = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
    start = end = 0
    for i in range(n):
        if i > end:
            lo[start : end + 1], hi[start : end + 1] = start, end + 1
            start = end = i
        reach = np.flatnonzero(coupled[i])
        end = max(end, int(reach.max()) if reach.size else i)
    lo[start:], hi[start:] = start, n
    return lo, hi


def run_blocks(
    y: np.ndarray,
    phis: np.ndarray,
    qs: np.ndarray,
    idx: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    h: np.ndarray,
    r: float,
    p0: np.ndarray,
    *,
    hold: int = 0,
    white: np.ndarray | None = None,
    lls: np.ndarray | None = None,
    hm: np.ndarray | None = None,
    nscaled: int = 0,
) -> float:
    """log p(y) by `block_filter` (arguments as there; `white` and `lls`, when given, receive the
    standardized innovations and each sample's log density; `hm` the gain drift on the first
    `nscaled` states, which disables the hold)."""
    empty = np.empty(0)
    hm = empty if hm is None else _f64(hm)
    white, lls = empty if white is None else white, empty if lls is None else lls
    ys, phis, qs, h, p0 = _f64(y), _f64(phis), _f64(qs), _f64(h), _f64(p0)
    idx, lo, hi = _i64(idx), _i64(lo), _i64(hi)
    hold = 0 if hm.size else int(hold)
    return float(block_filter(ys, phis, qs, idx, lo, hi, h, float(r), p0, hold, white, lls, hm, int(nscaled)))


def _f64(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64)


def _i64(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.int64)


def _root(cov: np.ndarray) -> np.ndarray:
    """Symmetric square roots S (S S^T = cov) of a stack of positive semi-definite matrices."""
    lam, vec = np.linalg.eigh(0.5 * (cov + np.swapaxes(cov, -1, -2)))
    return (vec * np.sqrt(np.clip(lam, 0.0, None))[..., None, :]) @ np.swapaxes(vec, -1, -2)


def simulate_blocks(
    phis: np.ndarray,
    qs: np.ndarray,
    idx: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    h: np.ndarray,
    r: float,
    p0: np.ndarray,
    rng: np.random.Generator,
    *,
    hm: np.ndarray | None = None,
    nscaled: int = 0,
) -> np.ndarray:
    """A draw of y_k (without a mean) of the model `block_filter` evaluates, states started in
    N(0, P0), at every sample of `idx` (gaps are the caller's to mark): the first `nscaled` states'
    part times the gain drift `hm` when given, the others' as they are, plus the white noise.
    Compiled, one pass."""
    n, t = phis.shape[1], idx.size
    x0 = _root(np.asarray(p0, dtype=float)) @ rng.standard_normal(n)
    z = rng.standard_normal((t, n))
    roots = _f64(_root(np.asarray(qs, dtype=float)))
    phis, idx, lo, hi, h = _f64(phis), _i64(idx), _i64(lo), _i64(hi), _f64(h)
    out = np.empty(t)
    if hm is not None and hm.size:
        scaled = np.where(np.arange(h.size) < nscaled, h, 0.0)
        propagate_blocks(phis, roots, idx, lo, hi, x0, z, scaled, out)
        rest = np.empty(t)
        propagate_blocks(phis, roots, idx, lo, hi, x0, z, h - scaled, rest)
        out = hm * out + rest
    else:
        propagate_blocks(phis, roots, idx, lo, hi, x0, z, h, out)
    return out + math.sqrt(r) * rng.standard_normal(t)

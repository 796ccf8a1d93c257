"""Exact Gaussian log-likelihood of a linear-Gaussian state-space model, by the Kalman filter.

    x_k = Phi_k x_{k-1} + w_k,  w_k ~ N(0, Q_k);   y_k = h . x_k + v_k,  v_k ~ N(0, r);   x_0 ~ N(0, P0)

O(T n^3) for n states, scalar observations; a NaN observation is a gap: the update is skipped, and
the likelihood is that of the observed samples only. The filter is the hot loop of every fit, so it
runs as the engine's compiled kernels (`vibinverse.engines.kalman`: `filter_steps` runs its
`block_filter`; `filter_two_states` for the common n = 2, one
oscillator, in scalars, ~5x faster); `log_likelihood_reference` is the same recursion in numpy,
for tests. Once the Riccati recursion has converged (to ~1e-14, over one period of the
slowest oscillation: `hold_samples`), the gain is held until a gap or another step, and a step
costs O(n): a one-hour record at 200 Hz takes ~0.02 s instead of ~0.15 s.

Two forms: one (Phi, Q) for every step (a uniform grid: `log_likelihood`, the fast path), or a table
of (Phi, Q) per unique step with an index per sample (irregular stamps: `log_likelihood_steps`;
`unique_steps` builds the index, `oscillator_tables` the exact discretization of damped oscillators
driven by continuous white noise, in closed form). `pointwise_log_likelihood` gives each sample's
one-step predictive log density, `simulate` draws the state process at the same steps.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import expm, solve_discrete_lyapunov

from vibinverse.engines.kalman import (  # the one recursion, its one-oscillator kernel and compiler live there
    block_layout,
    filter_two_states,
    njit,
    run_blocks,
)

_LOG_2PI = math.log(2.0 * math.pi)


def log_likelihood(
    y: NDArray[np.float64],
    phi: NDArray[np.float64],
    q: NDArray[np.float64],
    h: NDArray[np.float64],
    r: float,
    p0: NDArray[np.float64],
) -> float:
    """log p(y) for the model above; y may contain NaN gaps."""
    phis, qs = np.asarray(phi, dtype=np.float64)[None], np.asarray(q, dtype=np.float64)[None]
    return run_filter(y, phis, qs, _UNIFORM, h, r, p0, np.empty(0), np.empty(0))


def whiten(y, phi, q, h, r, p0) -> NDArray[np.float64]:
    """Standardized innovations e = L^-1 y (Sigma = L L^T the model's covariance of y); NaN at gaps.
    e.e = y^T Sigma^-1 y, which gives the Fisher information of the mean: sum of e(d mu_i) e(d mu_j)."""
    phis, qs = np.asarray(phi, dtype=np.float64)[None], np.asarray(q, dtype=np.float64)[None]
    out = np.empty(len(y))
    run_filter(y, phis, qs, _UNIFORM, h, r, p0, out, np.empty(0))
    return out


_UNIFORM = np.zeros(0, dtype=np.int64)  # an empty step index: every step is phis[0]


def hold_samples(phis: NDArray[np.float64]) -> int:
    """Samples over which the filter's gain must stay converged before it is held (`FREEZE_TOL`):
    one period, in steps, of the slowest oscillation among the eigenvalues of the step tables
    `phis` (a lightly damped oscillator's Riccati recursion converges with an oscillation whose
    changes dip towards 0 twice a period long before it has converged), plus one; 2 when no
    eigenvalue oscillates (walks and Ornstein-Uhlenbeck states converge monotonically)."""
    phis = np.asarray(phis, dtype=np.float64)
    angles = _two_state_angles(phis) if phis.shape[1:] == (2, 2) and phis.shape[0] <= 8 else None
    if angles is None:
        angles = np.abs(np.angle(np.linalg.eigvals(phis)))
    turning = angles[angles > 1e-12]
    if turning.size == 0:
        return 2
    return int(min(2**62, math.ceil(2.0 * math.pi / float(turning.min())) + 1))


def _two_state_angles(phis: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """|arg| of the eigenvalues of 2 x 2 tables in closed form (tr / 2 +- i sqrt(det - tr^2 / 4)),
    in scalars: 8 against 40-58 us for `np.linalg.eigvals` on the one table of a uniform grid (a
    likelihood call pays it). None unless every table clearly has a complex pair (real or nearly
    coincident eigenvalues go to `eigvals`)."""
    out = np.empty(phis.shape[0])
    for u, ((a, b), (c, d)) in enumerate(phis.tolist()):
        half, det = 0.5 * (a + d), a * d - b * c
        gap = det - half * half
        if not gap > 1e-6 * half * half:
            return None
        out[u] = math.atan2(math.sqrt(gap), half)
    return out


def log_likelihood_reference(y, phi, q, h, r, p0) -> float:
    """The same recursion in plain numpy (slow; for tests): `log_likelihood_steps_reference` with
    one step for every sample."""
    y = np.asarray(y, dtype=float)
    return log_likelihood_steps_reference(
        y, np.asarray(phi)[None], np.asarray(q)[None], np.zeros(y.size, dtype=np.int64), h, r, p0
    )


def stationary_covariance(phi: NDArray[np.float64], q: NDArray[np.float64]) -> NDArray[np.float64]:
    """P with P = Phi P Phi^T + Q (the process started in its stationary state)."""
    p = solve_discrete_lyapunov(phi, q)
    return 0.5 * (p + p.T)


def discretize_continuous(
    a: NDArray[np.float64], g: NDArray[np.float64], qc: float, dt: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(Phi, Q) of x' = A x + G w with continuous white noise w of intensity qc, step dt (Van Loan)."""
    n = a.shape[0]
    m = np.zeros((2 * n, 2 * n))
    m[:n, :n] = -a
    m[:n, n:] = qc * np.outer(g, g)
    m[n:, n:] = a.T
    e = expm(m * dt)
    phi = e[n:, n:].T
    q = phi @ e[:n, n:]
    return phi, 0.5 * (q + q.T)


# ------------------------------------------------------------------ per-step (Phi, Q): irregular stamps


def filter_steps(y, phis, qs, idx, h, r, p0, white, lls, freeze) -> float:
    """The Kalman filter with step k's (Phi, Q) = (phis[idx[k]], qs[idx[k]]) (idx empty: phis[0]
    for every step), any number of states: the engine's recursion
    (`vibinverse.engines.kalman.block_filter`) on the blocks the tables have (`block_layout`: the
    finest block-diagonal split; a dense model is one block). Writes the standardized innovations to
    `white` and each sample's log density to `lls` when they are not empty (NaN at gaps); `freeze`
    = m > 0 holds the converged gain after m calm samples (`is_calm`), until a gap or another step."""
    idx = np.zeros(len(y), dtype=np.int64) if len(idx) == 0 else idx
    lo, hi = block_layout(np.asarray(phis), np.asarray(qs), np.asarray(p0))
    return run_blocks(y, phis, qs, idx, lo, hi, h, r, p0, hold=freeze, white=white, lls=lls)


def run_filter(y, phis, qs, idx, h, r, p0, white, lls) -> float:
    """The filter for step tables (phis, qs) and step index idx (empty: uniform), the gain held
    after `hold_samples`: the two-state kernel for one oscillator, `filter_steps` otherwise."""
    args = _step_args(y, phis, qs, idx, h, r, p0)
    kernel = filter_two_states if args[1].shape[1] == 2 else filter_steps
    return float(kernel(*args, white, lls, hold_samples(args[1])))


def _step_args(y, phis, qs, idx, h, r, p0):
    c = lambda a: np.ascontiguousarray(a, dtype=np.float64)
    return c(y), c(phis), c(qs), np.ascontiguousarray(idx, dtype=np.int64), c(h), float(r), c(p0)


def log_likelihood_steps(y, phis, qs, idx, h, r, p0) -> float:
    """log p(y) when step k (from sample k - 1 to k) has (Phi, Q) = (phis[idx[k]], qs[idx[k]]);
    idx[0] is not read. y may contain NaN gaps."""
    return run_filter(y, phis, qs, idx, h, r, p0, np.empty(0), np.empty(0))


def pointwise_log_likelihood(y, phis, qs, idx, h, r, p0) -> NDArray[np.float64]:
    """Each sample's one-step predictive log density log p(y_k | y_1..y_{k-1}) (NaN at gaps; its
    nansum is `log_likelihood_steps`). A uniform grid: phis = phi[None], qs = q[None], idx zeros."""
    out = np.empty(len(y))
    run_filter(y, phis, qs, idx, h, r, p0, np.empty(0), out)
    return out


def whiten_steps(y, phis, qs, idx, h, r, p0) -> NDArray[np.float64]:
    """`whiten` with per-step (Phi, Q) as in `log_likelihood_steps`."""
    out = np.empty(len(y))
    run_filter(y, phis, qs, idx, h, r, p0, out, np.empty(0))
    return out


def log_likelihood_steps_reference(y, phis, qs, idx, h, r, p0) -> float:
    """The per-step recursion in plain numpy (slow; for tests)."""
    n = phis.shape[1]
    x, p, ll = np.zeros(n), np.array(p0, dtype=float), 0.0
    for k, yk in enumerate(y):
        if k > 0:
            phi, q = phis[idx[k]], qs[idx[k]]
            x, p = phi @ x, phi @ p @ phi.T + q
        if not np.isfinite(yk):
            continue
        s = h @ p @ h + r
        v = yk - h @ x
        gain = p @ h / s
        x, p = x + gain * v, p - np.outer(gain, h @ p)
        ll += -0.5 * (np.log(s) + _LOG_2PI + v * v / s)
    return float(ll)


def unique_steps(t: NDArray[np.float64], rtol: float = 1e-9) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """(steps, idx): the distinct steps of the stamps t, rounded to `rtol` of the median step, each
    the mean of the steps it stands for, and idx[k] (k >= 1) the entry of t[k] - t[k-1] (idx[0] = 0,
    unread). A uniform grid has one step; one with gaps of whole frames a few."""
    d = np.diff(np.asarray(t, dtype=float))
    if d.size == 0:
        return np.array([1.0]), np.zeros(1, dtype=np.int64)
    quantum = rtol * float(np.median(d))
    keys, inverse, counts = np.unique(np.round(d / quantum).astype(np.int64), return_inverse=True, return_counts=True)
    steps = np.bincount(inverse, weights=d, minlength=keys.size) / counts
    return steps, np.concatenate([[0], inverse]).astype(np.int64)


# Q11 = kappa * integral of g(s)^2 as a Taylor series while R t < 1/2 (R the largest rate of the
# oscillator's eigenvalues): the closed form cancels to ~eps / (w t)^2 at small w t; at R t >= 1/2 it
# loses less than a digit when underdamped (w t >= 1/2) and takes over
_SERIES_BELOW = 0.5
_SERIES_TERMS = 20  # Taylor terms of g; g^2 grows at 2R: truncation (2 R t)^18 / 18! < 2e-16


@njit(cache=True, fastmath=False, nogil=True)
def _rate(w, a):  # pragma: no cover - compiled
    """The largest rate of the oscillator's eigenvalues."""
    return w if a <= w else a + math.sqrt(a * a - w * w)


@njit(cache=True, fastmath=False, nogil=True)
def _impulse_taylor(w, a):  # pragma: no cover - compiled
    """Taylor coefficients g^(k)(0) / k!, k <= _SERIES_TERMS, of the impulse response g of
    q'' + 2 a q' + w^2 q (g(0) = 0, g'(0) = 1)."""
    nt = _SERIES_TERMS
    c = np.zeros(nt + 1)
    raw = np.zeros(nt + 1)
    raw[1] = 1.0
    fact = 1.0
    for k in range(nt - 1):
        raw[k + 2] = -2.0 * a * raw[k + 1] - w * w * raw[k]
    for k in range(1, nt + 1):
        fact *= k
        c[k] = raw[k] / fact
    return c


@njit(cache=True, fastmath=False, nogil=True)
def oscillator_fill(w, a, kappa, steps, phis, qs, b):  # pragma: no cover - compiled; tested against expm
    """Fill the 2 x 2 block at (b, b) of phis[u], qs[u] for every step steps[u]: the exact
    transition and process-noise covariance of x = (q, q'), q'' + 2 a q' + w^2 q = xi(t), xi white
    of intensity kappa. With g the impulse response, uS = g(t) = e^{-at} S, uC = e^{-at} C
    (C = cos(bt), S = sin(bt) / b, b^2 = w^2 - a^2; cosh / sinh when overdamped, 1 / t when critical):

        Phi = [[uC + a uS, uS], [-w^2 uS, uC - a uS]]
        Q11 = kappa / (4 w^2) ((1 - e^{-2at}) / a - 2 uS uC - 2 a uS^2)   (series in t when w t is small)
        Q12 = kappa uS^2 / 2
        Q22 = kappa / 4 ((1 - e^{-2at}) / a + 2 uS uC - 2 a uS^2)

    (Q = P_inf - Phi P_inf Phi^T with P_inf = kappa diag(1 / (4 a w^2), 1 / (4 a)), divided out so
    that a -> 0 stays exact)."""
    b2 = w * w - a * a
    rate = _rate(w, a)
    nt = _SERIES_TERMS
    c = _impulse_taylor(w, a)
    # g^2 = sum_n e_n s^n (n >= 2), exact up to n = nt + 1; Q11 / kappa = sum_n e_n t^(n+1) / (n + 1)
    coef = np.zeros(nt)
    for n in range(2, nt + 2):
        e = 0.0
        for j in range(max(1, n - nt), min(n - 1, nt) + 1):
            e += c[j] * c[n - j]
        coef[n - 2] = e / (n + 1)
    for u in range(steps.shape[0]):
        t = steps[u]
        if b2 > 0.0:
            bb = math.sqrt(b2)
            ea = math.exp(-a * t)
            us = ea * math.sin(bb * t) / bb
            uc = ea * math.cos(bb * t)
        elif b2 < 0.0:
            beta = math.sqrt(-b2)
            e1 = math.exp(-(a - beta) * t)
            uc = 0.5 * (e1 + math.exp(-(a + beta) * t))
            us = e1 * (-math.expm1(-2.0 * beta * t)) / (2.0 * beta)
        else:
            ea = math.exp(-a * t)
            us = ea * t
            uc = ea
        em = -math.expm1(-2.0 * a * t) / a if a > 0.0 else 2.0 * t  # (1 - e^{-2at}) / a
        phis[u, b, b] = uc + a * us
        phis[u, b, b + 1] = us
        phis[u, b + 1, b] = -w * w * us
        phis[u, b + 1, b + 1] = uc - a * us
        if rate * t < _SERIES_BELOW:  # sum coef[m] t^m, even and odd powers in two chains (latency)
            t2 = t * t
            even = 0.0
            odd = 0.0
            for m in range(nt - 2, -1, -2):
                even = even * t2 + coef[m]
                odd = odd * t2 + coef[m + 1]
            q11 = kappa * t * t * t * (even + t * odd)
        else:
            q11 = kappa / (4.0 * w * w) * (em - 2.0 * us * uc - 2.0 * a * us * us)
        q12 = 0.5 * kappa * us * us
        qs[u, b, b] = q11
        qs[u, b, b + 1] = q12
        qs[u, b + 1, b] = q12
        qs[u, b + 1, b + 1] = 0.25 * kappa * (em + 2.0 * us * uc - 2.0 * a * us * us)


@njit(cache=True, fastmath=False, nogil=True)
def held_oscillator_fill(w, a, kappa, steps, frame, phis, qs, b):  # pragma: no cover - compiled; tested
    """Fill the 2 x 2 block at (b, b) of phis[u], qs[u] for every step steps[u] of the oscillator
    q'' + 2 a q' + w^2 q = u(t) whose force u is held over each frame of `frame` seconds at an
    independent N(0, kappa / frame) value (a white force sampled at the frame rate, as the forward
    model draws it: `forward.motion.frame.simulate_linear`; the same low-frequency intensity kappa
    as `oscillator_fill`'s continuous noise). A step of m = round(step / frame) frames (dropped
    frames) holds m values over m equal parts h = step / m:

        Q(h) = kappa / h G G^T,  G = (integral of g over [0, h], g(h)),  Q(m h) = sum Phi(h)^j Q(h) Phi(h)^jT

    (g the impulse response; its integral is (1 - Phi_11) / w^2, a Taylor series while R h < 1/2),
    composed by squaring. Phi is `oscillator_fill`'s."""
    oscillator_fill(w, a, 1.0, steps, phis, qs, b)
    c = _impulse_taylor(w, a)
    rate = _rate(w, a)
    for u in range(steps.shape[0]):
        m = max(1, math.floor(steps[u] / frame + 0.5))
        h = steps[u] / m
        if m == 1:  # one frame (every step of a uniform grid): Phi(h) is the step's own
            f11, f12, f21, f22 = phis[u, b, b], phis[u, b, b + 1], phis[u, b + 1, b], phis[u, b + 1, b + 1]
        else:
            one = np.zeros((1, 2, 2))
            oscillator_fill(w, a, 1.0, np.array([h]), one, np.zeros((1, 2, 2)), 0)
            f11, f12, f21, f22 = one[0, 0, 0], one[0, 0, 1], one[0, 1, 0], one[0, 1, 1]
        g2 = f12  # g(h)
        if rate * h < _SERIES_BELOW:  # integral of g: sum c[k] h^(k+1) / (k+1)
            g1 = 0.0
            for k in range(_SERIES_TERMS, 0, -1):
                g1 = g1 * h + c[k] / (k + 1)
            g1 *= h * h
        else:
            g1 = (1.0 - f11) / (w * w)
        v = kappa / h
        q11, q12, q22 = v * g1 * g1, v * g1 * g2, v * g2 * g2
        # (Phi, Q) of m parts by squaring: (Pa, Qa) then (Pb, Qb) is (Pb Pa, Pb Qa Pb^T + Qb)
        r11, r12, r21, r22, s11, s12, s22 = 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0
        while m:
            if m & 1:  # (R, S) then (F, Q)
                t11 = f11 * s11 + f12 * s12
                t12 = f11 * s12 + f12 * s22
                t21 = f21 * s11 + f22 * s12
                t22 = f21 * s12 + f22 * s22
                s11 = t11 * f11 + t12 * f12 + q11
                s12 = t11 * f21 + t12 * f22 + q12
                s22 = t21 * f21 + t22 * f22 + q22
                r11, r12, r21, r22 = (
                    f11 * r11 + f12 * r21,
                    f11 * r12 + f12 * r22,
                    f21 * r11 + f22 * r21,
                    f21 * r12 + f22 * r22,
                )
            m >>= 1
            if m:  # (F, Q) then (F, Q)
                t11 = f11 * q11 + f12 * q12
                t12 = f11 * q12 + f12 * q22
                t21 = f21 * q11 + f22 * q12
                t22 = f21 * q12 + f22 * q22
                q11, q12, q22 = t11 * f11 + t12 * f12 + q11, t11 * f21 + t12 * f22 + q12, t21 * f21 + t22 * f22 + q22
                f11, f12, f21, f22 = (
                    f11 * f11 + f12 * f21,
                    f11 * f12 + f12 * f22,
                    f21 * f11 + f22 * f21,
                    f21 * f12 + f22 * f22,
                )
        qs[u, b, b] = s11
        qs[u, b, b + 1] = s12
        qs[u, b + 1, b] = s12
        qs[u, b + 1, b + 1] = s22


def held_stationary(phi: NDArray[np.float64], q: NDArray[np.float64]) -> NDArray[np.float64]:
    """The stationary covariance P = Phi P Phi^T + Q of a stable 2 x 2 step (the held force's
    oscillator: `held_oscillator_fill`), by the 3 x 3 linear system of its distinct entries
    (infinite when Phi is not stable, an eigenvalue at 1 to rounding: an undamped oscillator under
    noise; a step decays by e^-1e-12 at least where a damping ratio of 1e-6 meets 0.02 Hz). Compiled:
    it runs in every frame likelihood call (23 us in numpy, a tenth of the call)."""
    out = np.empty((2, 2))
    _held_stationary(np.ascontiguousarray(phi, dtype=np.float64), np.ascontiguousarray(q, dtype=np.float64), out)
    return out


@njit(cache=True, fastmath=False, nogil=True)
def _held_stationary(phi, q, out):  # pragma: no cover - compiled; tested against scipy's Lyapunov solver
    f11, f12, f21, f22 = phi[0, 0], phi[0, 1], phi[1, 0], phi[1, 1]
    tr, det = f11 + f22, f11 * f22 - f12 * f21
    # Jury: both eigenvalues inside the unit circle iff |det| < 1 and |tr| < 1 + det (with margin)
    if not (abs(det) < 1.0 - 1e-12 and 1.0 - tr + det > 1e-12 and 1.0 + tr + det > 1e-12):
        v = np.inf if (q[0, 0] != 0.0 or q[0, 1] != 0.0 or q[1, 1] != 0.0) else 0.0
        out[:, :] = v
        return
    # (I - M) p = (q11, q12, q22), M the map of P's distinct entries under Phi P Phi^T; Cramer's rule
    a11, a12, a13 = 1.0 - f11 * f11, -2.0 * f11 * f12, -f12 * f12
    a21, a22, a23 = -f11 * f21, 1.0 - f11 * f22 - f12 * f21, -f12 * f22
    a31, a32, a33 = -f21 * f21, -2.0 * f21 * f22, 1.0 - f22 * f22
    b1, b2, b3 = q[0, 0], q[0, 1], q[1, 1]
    d = a11 * (a22 * a33 - a23 * a32) - a12 * (a21 * a33 - a23 * a31) + a13 * (a21 * a32 - a22 * a31)
    p11 = (b1 * (a22 * a33 - a23 * a32) - a12 * (b2 * a33 - a23 * b3) + a13 * (b2 * a32 - a22 * b3)) / d
    p12 = (a11 * (b2 * a33 - a23 * b3) - b1 * (a21 * a33 - a23 * a31) + a13 * (a21 * b3 - b2 * a31)) / d
    p22 = (a11 * (a22 * b3 - b2 * a32) - a12 * (a21 * b3 - b2 * a31) + b1 * (a21 * a32 - a22 * a31)) / d
    out[0, 0], out[0, 1], out[1, 0], out[1, 1] = p11, p12, p12, p22


def oscillator_tables(
    omega: float, zeta: float, steps: NDArray[np.float64], kappa: float = 1.0
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(Phi, Q) of shape (len(steps), 2, 2): the exact discretization of x = (q, q') with
    q'' + 2 zeta omega q' + omega^2 q = xi(t), xi continuous white noise of intensity kappa, over each
    step (closed form for under-, critically and over-damped oscillators: within 1e-12 of the Van
    Loan matrix exponential of `discretize_continuous`, within 2e-14 of a 150-digit one; tested)."""
    steps = np.ascontiguousarray(steps, dtype=np.float64).reshape(-1)
    phis, qs = np.zeros((steps.size, 2, 2)), np.zeros((steps.size, 2, 2))
    oscillator_fill(float(omega), float(zeta * omega), float(kappa), steps, phis, qs, 0)
    return phis, qs


def oscillator_stationary(omega: float, zeta: float, kappa: float = 1.0) -> NDArray[np.float64]:
    """The stationary covariance of that oscillator, kappa diag(1 / (4 zeta omega^3), 1 / (4 zeta omega))
    (infinite when undamped and driven)."""
    if kappa == 0.0:
        return np.zeros((2, 2))
    a = zeta * omega
    return np.diag([kappa / (4.0 * a * omega * omega), kappa / (4.0 * a)]) if a > 0 else np.diag([np.inf, np.inf])


@njit(cache=True, fastmath=False, nogil=True)
def _propagate_states(phis, roots, idx, x0, z, out):  # pragma: no cover - compiled; tested by its moments
    n = phis.shape[1]
    for i in range(n):
        out[0, i] = x0[i]
    for k in range(1, out.shape[0]):
        u = idx[k]
        for i in range(n):
            s = 0.0
            for j in range(n):
                s += phis[u, i, j] * out[k - 1, j] + roots[u, i, j] * z[k, j]
            out[k, i] = s


def _root(cov: NDArray[np.float64]) -> NDArray[np.float64]:
    """Symmetric square roots S (S S^T = cov) of a stack of positive semi-definite matrices."""
    lam, vec = np.linalg.eigh(0.5 * (cov + np.swapaxes(cov, -1, -2)))
    return (vec * np.sqrt(np.clip(lam, 0.0, None))[..., None, :]) @ np.swapaxes(vec, -1, -2)


def simulate(phis, qs, idx, h, r, p0, rng: np.random.Generator) -> NDArray[np.float64]:
    """A draw of y_k = h . x_k + v_k, k < len(idx), of the model of `log_likelihood_steps`, started
    from x_0 ~ N(0, P0) (the stationary covariance: the process the likelihood assumes)."""
    phis = np.ascontiguousarray(phis, dtype=np.float64)
    idx = np.ascontiguousarray(idx, dtype=np.int64)
    n, m = idx.size, phis.shape[1]
    x0 = _root(np.asarray(p0, dtype=float)) @ rng.standard_normal(m)
    z = rng.standard_normal((n, m))
    states = np.empty((n, m))
    _propagate_states(phis, np.ascontiguousarray(_root(np.asarray(qs, dtype=float))), idx, x0, z, states)
    return states @ np.asarray(h, dtype=float) + math.sqrt(r) * rng.standard_normal(n)

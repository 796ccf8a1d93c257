"""A scene-less generic modal model: a measured series as stochastic resonances, deterministic lines
and nuisance terms, all in one Kalman filter (`ModalModel`, registered as "modal").

    y(t) = (1 + g(t)) [level + sum_i q_i(t) + sum_j A_j cos(2 pi f_j t + phase_j)] + d(t) + c(t) + e(t)

- q_i: K resonances (`modes[i].frequency` f in Hz, `modes[i].damping_ratio` zeta,
  `modes[i].rms` the stationary RMS in the intensity's units): q'' + 2 zeta w q' + w^2 q = xi(t),
  w = 2 pi f, xi continuous white noise of intensity kappa = 4 zeta w^3 rms^2. Two states (q, q').
- lines: L deterministic sinusoids (`lines[j].frequency`, `.amplitude`, `.phase`): the mean.
- free decays: D rings from one excitation (`decays[j].frequency`, `.damping_ratio`,
  `.amplitude`; `vibinverse.terms.decay.FreeDecay`): the oscillator without process noise, its
  state drawn N(0, A^2 diag(1, w^2)) at the onset (`modal.onset` in seconds, else
  `excitation_onset`: the first sample, or a blow's; its step gets a table entry of its own),
  zero before; all decays share it (one excitation). The filter's engine only (a
  ring is not stationary: no Whittle); scaled by the gain drift like the modes.
- d: drift (`drift.rate`, the RMS change per sqrt(second)): a random walk started at 0 (so that
  `level` is the series' level at the first sample), or an integrated random walk (drift
  "integrated": a slope state driven by white noise of intensity rate^2, level and slope started
  at 0; `drift.rate` is then in intensity per s^1.5).
- c: coloured noise. "ar1": one Ornstein-Uhlenbeck state (`ar.rms`, its stationary RMS, and
  `ar.time`, the correlation time in s; sampled, an AR(1) with phi = exp(-dt / time)). "1/f": Ornstein-
  Uhlenbeck states of equal variance `flicker.rms`^2 / their number, one for each decade from one
  cycle per record to the Nyquist frequency (at least three; `flicker_terms`: four on 20 s at
  200 Hz), their corners spread evenly in log frequency from one cycle per record to
  `flicker.corner` (Hz; `flicker_times`): a spectrum ~ 1/f between those, ~ 1/f^2 above. A 1/f
  term whose upper corner was fixed at 100 cycles per record (5 Hz on 20 s) left the shoulder of
  noise with a 16 Hz corner to a false broad "mode"; one fixed at Nyquist under-predicted the noise
  near a 3.5 Hz mode of such data, which widened (damping ratios 2x too large).
- e: white sensor noise (`noise.sigma`); absent (`white` false) only beside a coloured noise c,
  which then is the whole noise: where AR(1) noise alone describes the data, sigma is not
  identified (flat in ln sigma down to its prior's bound: emcee took 9,500 steps, 39 s, on 4,000
  samples, and PSIS refused the Laplace proposal), so the order search removes it there.
- g: a multiplicative gain drift (a cloud dims the whole signal, the vibration included; `gain`
  J > 0 cosines, `gain.a1` .. `gain.aJ`): g(t) = sum_j a_j cos(pi j u), u = (t - t0) / span, from
  0.5 to J / 2 cycles per record (J = 6 by default: a smooth change over the record). Given the
  coefficients the model stays linear-Gaussian: the level and the lines are multiplied by
  1 + g(t_k), and the modes' observation row by the same factor at each sample (the filter's
  observation vector varies per sample, `vibinverse.engines.kalman.block_filter`'s `hm`), so the likelihood is exact.
  1 + g must stay positive.

Every random block is discretized exactly over each time step (`_fill_tables`, compiled): the
oscillator by the closed form of the Van Loan matrix exponential (Phi = e^{A dt},
Q = int_0^dt e^{As} G G^T e^{A^T s} ds kappa; a Taylor series of the impulse response for Q11 when
the step is short against the oscillator's rate, where the closed form cancels), the walks and the
Ornstein-Uhlenbeck states by their elementary forms. A uniform grid has one step; irregular stamps
(jitter, dropped frames) a table of the distinct steps (`vibinverse.kalman.unique_steps`, rounded to
1e-9 of the median step) with an index per sample: the same exact discretization per step. NaN
samples are gaps. The state transition is block diagonal (2 x 2 and 1 x 1 blocks), and the engine
(`vibinverse.engines.kalman.block_filter`, compiled, O(T)) uses that: the covariance is propagated
block pair by block pair in closed form (O(n^2) a step instead of O(n^3) for n states), and once the
gain and the innovation variance have reached the Riccati recursion's fixed point (their change between
two observed samples of the same step, extrapolated geometrically, below 1e-14 of their scale) the
gain is held until a gap or another step: O(n) a step from there, the same numbers to rounding
(tested against the plain numpy filter to 1e-10). White noise alone has one dummy state nobody sees.
Lightly damped modes and slow drifts converge late (a random walk of step variance q in white noise
of variance r over ~sqrt(r / q) steps), so the hold saves most on long records of damped modes.

Label switching: the modes (and the lines) are exchangeable, so `log_likelihood` is -inf unless
the modes' frequencies are strictly increasing, and the lines' too (a sorted-frequency constraint;
the priors of all modes are the same window, lo..Nyquist). Mode 0 is always the lowest.

The table: `{"modal": {"modes": 3, "lines": 0, "decays": 0, "drift": True, "noise": "ar1"}}`; `drift` is False
(none), True or "walk", or "integrated"; `noise` is "white", "ar1" or "1/f"; `white` is True
(default) or False (no white sensor noise: only beside "ar1" or "1/f"). Optional
`"start": {name: value}` is the first starting point (the order search writes its optimum there),
and `"values": {name: value}` the values of parameters that are not free (default: the start,
else the first spectral guess). `"windows": [[lo, hi], ...]` (Hz) narrows the frequency prior of
each line whose start lies in one to that window (the order search writes there the band next to a
resonance in which it found a line, `model_order.settle_near_lines`: the line was searched over
that band, so its detection test's look-elsewhere term is the band's, not the whole spectrum's).

The Fisher information (`fisher`) is numerical: the observed information, central finite
differences of the exact log-likelihood with steps of a tenth of each parameter's width.
"""

from __future__ import annotations

import copy
import functools
import math
import threading
from dataclasses import dataclass
from typing import Any

import numpy as np

from vibinverse.engines.kalman import block_filter, simulate_blocks
from vibinverse.engines.whittle import (
    Periodogram,
    block_layout,
    dot,
    level_term,
    level_window,
    lines_sum,
    shared_jump,
    walk_step_variance,
)
from vibinverse.errors import SceneError, Unsupported
from vibinverse.io.file_basics import steady
from vibinverse.io.series import MIN_CYCLES, Series, evenly_spaced
from vibinverse.kalman import filter_two_states, njit, unique_steps
from vibinverse.models.base import (
    LineTest,
    SignalModel,
    intensity_units,
    observed_information,
    parameter_units,
    register_model,
)
from vibinverse.priors import Prior
from vibinverse.terms.base import (
    FREE_DECAY_FORM,
    INTEGRATED_WALK_FORM,
    OSCILLATOR_FORM,
    WALK_FORM,
    DataFacts,
    Term,
)
from vibinverse.terms.decay import FreeDecay, excitation_onset, ring_start
from vibinverse.terms.drift import GAIN_LIMIT, GAIN_TERMS, gain_basis, gain_names
from vibinverse.terms.noise import flicker_terms
from vibinverse.terms.nuisance import DRIFT_KINDS, DRIFT_TERMS, NOISE_KINDS, NOISE_TERMS, NuisanceKinds
from vibinverse.terms.resonance import Oscillator

#: records at least this long, uniform, without gaps or a gain drift, are fitted by Whittle's
#: likelihood (`vibinverse.engines.whittle`; `ModalModel.spectral`), 10x cheaper per call than the
#: Kalman filter there and within a few percent of its interval widths (tests/vibinverse/engines/test_whittle.py)
WHITTLE_MIN_SAMPLES = 20_000
#: a mode or line this close to a component whose detection test removes it (Fourier bins, plus
#: half-power half-widths of either) is refitted first with the null (`near_parameters`)
NEAR_REACH_BINS, NEAR_REACH_WIDTHS = 20.0, 5.0
_LOG_2PI = math.log(2.0 * math.pi)


# ------------------------------------------------------------------ the model's order


@dataclass(frozen=True)
class ModalSpec(NuisanceKinds):
    """The model's order: K modes, L lines, the drift ("none", "walk", "integrated"), the
    coloured noise ("white", "ar1", "1/f"), the gain drift's number of cosines (0: none), and
    whether the white sensor noise is there (`white`; False only beside a coloured noise, which
    then describes the noise alone: `noise.sigma` is not a parameter)."""

    modes: int = 0
    lines: int = 0
    drift: str = "none"
    noise: str = "white"
    gain: int = 0
    white: bool = True
    decays: int = 0
    #: the free decays' onset, seconds after the first stamp (None: read from the data,
    #: `excitation_onset`); the order search sets it where the likelihood is highest
    onset: float | None = None

    def __post_init__(self) -> None:
        if not self.white and not self.coloured:
            raise SceneError("modal.white: false needs a coloured noise (noise = 'ar1' or '1/f') in its place")

    def nuisance_terms(self) -> list[Term]:
        """The drift's and the coloured noise's terms, those there (`DRIFT_TERMS`, `NOISE_TERMS`)."""
        return [cls() for cls in (DRIFT_TERMS[self.drift], NOISE_TERMS[self.noise]) if cls is not None]

    @classmethod
    def from_table(cls, table: dict[str, Any]) -> ModalSpec:
        """The order a table's `modal` sub-table gives (absent keys: none of that component)."""
        m = table.get("modal")
        if m is None:
            m = {}
        if not isinstance(m, dict):
            raise SceneError("modal: must be a table, e.g. {modes = 2, lines = 0, drift = true, noise = 'ar1'}")
        keys = {"modes", "lines", "decays", "onset", "drift", "noise", "gain", "white", "values", "start", "windows"}
        unknown = set(m) - keys
        if unknown:
            raise SceneError(
                f"modal.{sorted(unknown)[0]}: unknown key; allowed: modes, lines, decays, onset, drift, noise, gain, "
                "white, values, start, windows"
            )
        out = {}
        for key in ("modes", "lines", "decays"):
            v = m.get(key, 0)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 0 <= int(v) <= 20:
                raise SceneError(f"modal.{key}: {v!r}; allowed: an integer in [0, 20]")
            out[key] = int(v)
        drift = m.get("drift", False)
        if drift is True:
            drift = "walk"
        elif drift is False or drift is None:
            drift = "none"
        if drift not in DRIFT_KINDS:
            raise SceneError(f"modal.drift: {m.get('drift')!r}; allowed: false, true, 'walk', 'integrated'")
        noise = m.get("noise", "white")
        if noise not in NOISE_KINDS:
            raise SceneError(f"modal.noise: {noise!r}; allowed: {', '.join(repr(k) for k in NOISE_KINDS)}")
        gain = m.get("gain", False)
        if gain is True:
            gain = GAIN_TERMS
        elif gain is False or gain is None:
            gain = 0
        if isinstance(gain, bool) or not isinstance(gain, (int, np.integer)) or not 0 <= int(gain) <= 24:
            raise SceneError(f"modal.gain: {m.get('gain')!r}; allowed: false, true ({GAIN_TERMS} cosines) or 0..24")
        white = m.get("white", True)
        if not isinstance(white, (bool, np.bool_)):
            raise SceneError(f"modal.white: {white!r}; allowed: true, or false beside noise = 'ar1' or '1/f'")
        onset = m.get("onset")
        number = isinstance(onset, (int, float, np.number)) and not isinstance(onset, bool)
        if onset is not None and not (number and 0 <= float(onset) < math.inf):
            raise SceneError(f"modal.onset: {onset!r}; allowed: seconds >= 0 after the first sample (decays' onset)")
        onset = None if onset is None else float(onset)
        return cls(out["modes"], out["lines"], drift, noise, int(gain), bool(white), out["decays"], onset)

    def table(self) -> dict[str, Any]:
        """The `modal` sub-table of this order."""
        return {
            "modes": self.modes,
            "lines": self.lines,
            "drift": self.drifting and self.drift,
            "noise": self.noise,
            "gain": self.gain,
            "white": self.white,
            **({"decays": self.decays} if self.decays else {}),
            **({"onset": self.onset} if self.decays and self.onset is not None else {}),
        }

    def names(self) -> list[str]:
        """Every parameter of this order, in a fixed order."""
        out = ["level"]
        for i in range(self.modes):
            out += [f"modes[{i}].frequency", f"modes[{i}].damping_ratio", f"modes[{i}].rms"]
        for j in range(self.lines):
            out += [f"lines[{j}].frequency", f"lines[{j}].amplitude", f"lines[{j}].phase"]
        for j in range(self.decays):
            out += FreeDecay(f"decays[{j}]").names()
        for term in self.nuisance_terms():
            out += term.names()
        out += gain_names(self.gain)
        if self.white:
            out.append("noise.sigma")
        return out


# ------------------------------------------------------------------ compiled kernels


@njit(cache=True, fastmath=False, nogil=True)
def _oscillator(w, a, kappa, t, phi, q, o):  # pragma: no cover - compiled; tested against expm
    """The exact (Phi, Q) of x = (q, q'), q'' + 2 a q' + w^2 q = xi (intensity kappa), over a step
    t, written into the 2 x 2 block at (o, o). With uS = e^{-at} sin(bt) / b, uC = e^{-at} cos(bt),
    b^2 = w^2 - a^2 (sinh / cosh when overdamped, t when critical):

        Phi = [[uC + a uS, uS], [-w^2 uS, uC - a uS]]
        Q11 = kappa / (4 w^2) ((1 - e^{-2at}) / a - 2 uS uC - 2 a uS^2)
        Q12 = kappa uS^2 / 2
        Q22 = kappa / 4 ((1 - e^{-2at}) / a + 2 uS uC - 2 a uS^2)

    Q11 cancels to ~eps / (rate t)^2 at short steps: there it is kappa int_0^t g(s)^2 ds from the
    Taylor series of the impulse response g (g'' = -2a g' - w^2 g, g(0) = 0, g'(0) = 1)."""
    b2 = w * w - a * a
    if b2 > 0.0:
        bb = math.sqrt(b2)
        ea = math.exp(-a * t)
        us = ea * math.sin(bb * t) / bb
        uc = ea * math.cos(bb * t)
        rate = w
    elif b2 < 0.0:
        beta = math.sqrt(-b2)
        e1 = math.exp(-(a - beta) * t)
        uc = 0.5 * (e1 + math.exp(-(a + beta) * t))
        us = e1 * (-math.expm1(-2.0 * beta * t)) / (2.0 * beta)
        rate = a + beta
    else:
        ea = math.exp(-a * t)
        us = ea * t
        uc = ea
        rate = a
    em = -math.expm1(-2.0 * a * t) / a if a > 0.0 else 2.0 * t
    phi[o, o] = uc + a * us
    phi[o, o + 1] = us
    phi[o + 1, o] = -w * w * us
    phi[o + 1, o + 1] = uc - a * us
    if rate * t < 0.5:
        nt = 18
        c = np.zeros(nt + 1)  # c[k] = g^(k)(0) t^k / k!
        c[1] = t
        for k in range(nt - 1):  # (k+2)(k+1) c_{k+2} = -2a (k+1) c_{k+1} t - w^2 c_k t^2
            c[k + 2] = (-2.0 * a * (k + 1) * c[k + 1] * t - w * w * c[k] * t * t) / ((k + 2) * (k + 1))
        acc = 0.0
        for n in range(2 * nt, 1, -1):  # int_0^t g^2 = t sum_n e_n / (n + 1), e_n = sum_j c_j c_{n-j}
            e = 0.0
            for j in range(max(1, n - nt), min(n - 1, nt) + 1):
                e += c[j] * c[n - j]
            acc += e / (n + 1)
        q11 = kappa * t * acc
    else:
        q11 = kappa / (4.0 * w * w) * (em - 2.0 * us * uc - 2.0 * a * us * us)
    q12 = 0.5 * kappa * us * us
    q[o, o] = q11
    q[o, o + 1] = q12
    q[o + 1, o] = q12
    q[o + 1, o + 1] = 0.25 * kappa * (em + 2.0 * us * uc - 2.0 * a * us * us)


@njit(cache=True, fastmath=False, nogil=True)
def _fill_tables(kinds, pars, offsets, steps, phis, qs, p0):  # pragma: no cover - compiled
    """(Phi, Q) of every block for every step, and the initial covariance P0. Block b starts at
    state offsets[b]; kinds: oscillator (w, a = zeta w, rms), random walk (rate^2), integrated
    random walk (rate^2), Ornstein-Uhlenbeck (time, variance), free decay (w, a = zeta w, amplitude:
    its onset's covariance is written by `FreeDecay.excite`): `vibinverse.terms.base`'s forms."""
    phis[:] = 0.0
    qs[:] = 0.0
    p0[:] = 0.0
    for b in range(kinds.shape[0]):
        o = offsets[b]
        kind = kinds[b]
        if kind == OSCILLATOR_FORM:
            w, a, rms = pars[b, 0], pars[b, 1], pars[b, 2]
            kappa = 4.0 * a * w * w * rms * rms
            for u in range(steps.shape[0]):
                _oscillator(w, a, kappa, steps[u], phis[u], qs[u], o)
            p0[o, o] = rms * rms
            p0[o + 1, o + 1] = w * w * rms * rms
        elif kind == FREE_DECAY_FORM:  # no process noise; its onset's covariance is written after
            for u in range(steps.shape[0]):
                _oscillator(pars[b, 0], pars[b, 1], 0.0, steps[u], phis[u], qs[u], o)
        elif kind == WALK_FORM:
            for u in range(steps.shape[0]):
                phis[u, o, o] = 1.0
                qs[u, o, o] = pars[b, 0] * steps[u]
        elif kind == INTEGRATED_WALK_FORM:
            for u in range(steps.shape[0]):
                dt = steps[u]
                phis[u, o, o] = 1.0
                phis[u, o, o + 1] = dt
                phis[u, o + 1, o + 1] = 1.0
                qs[u, o, o] = pars[b, 0] * dt * dt * dt / 3.0
                qs[u, o, o + 1] = pars[b, 0] * dt * dt / 2.0
                qs[u, o + 1, o] = pars[b, 0] * dt * dt / 2.0
                qs[u, o + 1, o + 1] = pars[b, 0] * dt
        else:
            tau, var = pars[b, 0], pars[b, 1]
            for u in range(steps.shape[0]):
                phis[u, o, o] = math.exp(-steps[u] / tau)
                qs[u, o, o] = -var * math.expm1(-2.0 * steps[u] / tau)
            p0[o, o] = var


@njit(cache=True, fastmath=False, nogil=True)
def _lines_mean(t, level, f, a, ph, out):  # pragma: no cover - compiled
    for k in range(t.shape[0]):
        acc = level
        for j in range(f.shape[0]):
            acc += a[j] * math.cos(2.0 * math.pi * f[j] * t[k] + ph[j])
        out[k] = acc


def whittle_engine(
    series: Series, gaps: bool, gain: bool, integrated: bool, bins: int = 1, drifting: bool = True
) -> Periodogram | None:
    """Whittle's engine for a long record without gaps whose
    steps are steady (`steady`: read on the regular grid from its first to its last stamp), for a
    model without a gain drift or an integrated walk; None: the Kalman filter's exact likelihood.
    Long: at least `WHITTLE_MIN_SAMPLES` samples, or any length below a logger's anti-alias roll-off
    (`Series.passband`: the filter sees the whole band, and its ln L less the ordinates above the
    top, `ModalModel.above_passband`, misled the search of a 20 min record into five modes and
    free decays in 15 minutes; Whittle's on the band found the three in seconds). `bins` > 1: the
    ordinates grouped (`Periodogram`).

    On the record's first differences for a model with a drift (a walk has no periodogram), on the
    record itself without one. Why not always the differences: their transform at every ordinate is
    (1 - e^{-iw}) Y_j + (y_m - y_0), the stationary part's end-to-end jump, one random number shared
    by all ordinates; Whittle's likelihood counts it as independent noise in each, weighted most
    where the differenced density is low. On 40 min 10 Hz records of three modes (simulated exactly,
    white noise, no drift) the differences' estimates of the strongest mode's damping ratio spread
    four times the intervals' sd (two of 30 at a quarter and a half of the truth), and its
    intervals held the truth in 12 of 30; the record's periodogram's in 27 of 30, all three modes'
    damping ratios in 0.89 +- 0.03 (90 intervals), as with the Kalman filter's exact likelihood
    (0.90 +- 0.03). With a drift the jump is one term shared by the ordinates
    (`vibinverse.engines.whittle.shared_jump`)."""
    short = series.time.size < WHITTLE_MIN_SAMPLES and series.passband is None
    if gaps or gain or integrated or short or not steady(series.time):
        return None
    top = None if series.passband is None else min(0.5, series.passband * series.dt)
    return periodogram(series.time.size, bins, top, 1 if drifting else 0)


@functools.lru_cache(maxsize=8)
def periodogram(n: int, bins: int, top: float | None = None, differences: int = 1) -> Periodogram:
    """The `Periodogram` of a record of n samples or of its differences (its ordinates grouped
    `bins` at a time, those above `top` cycles per sample left out: a logger's anti-alias roll-off), shared:
    the order search builds dozens of models of one record (14 ms each at 720,000 samples), and a
    periodogram is never changed after it is made."""
    return Periodogram(n, differences, bins, top)


def wrap_phase(phase: float) -> float:
    """A phase (rad) wrapped into [-pi, pi); 0 when it is not finite."""
    p = float(phase)
    return (p + math.pi) % (2.0 * math.pi) - math.pi if math.isfinite(p) else 0.0


# ------------------------------------------------------------------ spectra (starts, the order search)


def spectrum(y: np.ndarray, dt: float, t: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(frequencies, power) on (0, Nyquist] of the de-meaned series, gaps filled with 0, unpadded:
    power = |sum y e^{-i w t}|^2 / N_valid, whose mean is sigma^2 for white noise of sd sigma and
    whose sum over the one-sided bins is N / 2 x the variance (Parseval).

    With irregular stamps `t` (jitter, dropped frames) the same power at the stamps themselves: the
    floating-mean Lomb-Scargle periodogram of the valid samples (nifty-ls, "psd" normalization, which
    is the formula above on a uniform grid), on the grid k / (n dt) up to 1 / (2 dt), dt the median
    step. Treating the samples as evenly spaced would move every peak by the fraction of frames
    dropped (5 % at 10 % dropped), more than a line's width."""
    good = np.isfinite(y)
    if t is not None and t.size > 2 and not evenly_spaced(t):
        import nifty_ls

        tt = np.ascontiguousarray(t[good], dtype=np.float64)
        n = round((t[-1] - t[0]) / dt) + 1
        df = 1.0 / (n * dt)
        nf = max(n // 2, 2)
        yy = np.ascontiguousarray(y[good] - np.mean(y[good]), dtype=np.float64)
        res = nifty_ls.lombscargle(tt, yy, fmin=df, fmax=nf * df, Nf=nf, normalization="psd")
        return np.asarray(res.freq(), dtype=float), np.asarray(res.power, dtype=float)
    r = np.where(good, y - np.nanmean(y), 0.0)
    power = np.abs(np.fft.rfft(r)) ** 2 / max(int(good.sum()), 1)
    freqs = np.fft.rfftfreq(r.size, dt)
    return freqs[1:], power[1:]


def smooth(power: np.ndarray, width: int) -> np.ndarray:
    """A boxcar running mean of `width` bins (odd), edges by the available bins."""
    width = max(1, int(width) | 1)
    if width == 1:
        return power.copy()
    kern = np.ones(width)
    return np.convolve(power, kern, "same") / np.convolve(np.ones_like(power), kern, "same")


def spectral_peaks(
    freqs: np.ndarray,
    power: np.ndarray,
    band: tuple[float, float],
    width: int,
    separation: float,
    limit: int | None = None,
) -> list[tuple[float, float]]:
    """Local maxima of the smoothed power inside `band`, strongest first, at least `separation` Hz
    apart, the first `limit` (None: all): (frequency, smoothed power / median smoothed power). The
    first and last bins count as maxima when they exceed their one neighbour: a sway of 1-2 cycles
    in the record peaks in the first Fourier bin (`spectrum` starts at one cycle per record)."""
    sm = smooth(power, width)
    sel = (freqs >= band[0]) & (freqs <= band[1])
    floor = float(np.median(sm[sel])) if sel.any() else 1.0
    idx = np.flatnonzero(sel)
    padded = np.concatenate([[-np.inf], sm, [-np.inf]])
    peaks = [i for i in idx if sm[i] >= padded[i] and sm[i] >= padded[i + 2]]
    peaks.sort(key=lambda i: -sm[i])
    out: list[tuple[float, float]] = []
    for i in peaks:
        if limit is not None and len(out) >= limit:
            break
        if all(abs(freqs[i] - f) >= separation for f, _ in out):
            out.append((float(freqs[i]), float(sm[i] / max(floor, 1e-300))))
    return out


def background(freqs: np.ndarray, power: np.ndarray, reach: float = 0.5) -> np.ndarray:
    """The power's smooth background at each frequency f: the median of the raw power over
    f (1 +- reach), at the first 20 bins and on log-spaced nodes (10 per octave) after, interpolated
    in ln f. The window's width grows with f, so it follows a drift's or a coloured noise's power
    law and knee, which a window of fixed width smears; being symmetric in f, its median is the
    curve's value at f wherever the curve is monotone. A resonance or a line, a few bins in a window
    of many, stands above it."""
    f0, f1 = float(freqs[0]), float(freqs[-1])
    nodes = np.exp(np.linspace(math.log(f0), math.log(f1), max(2, math.ceil(10 * math.log2(f1 / f0)) + 1)))
    nodes = np.union1d(freqs[:20], nodes)  # the first bins themselves, whose windows hold few bins
    lo = np.searchsorted(freqs, nodes * (1.0 - reach), "left")
    hi = np.maximum(np.searchsorted(freqs, nodes * (1.0 + reach), "right"), lo + 1)
    med = np.array([np.median(power[a:b]) for a, b in zip(lo, hi)])
    return np.exp(np.interp(np.log(freqs), np.log(nodes), np.log(np.maximum(med, 1e-300))))


def line_windows(raw: Any) -> tuple[tuple[float, float], ...]:
    """The `modal.windows` of a table as ((lo, hi), ...) in Hz; a one-line SceneError naming the
    key unless each is a pair of finite numbers 0 <= lo < hi."""
    if raw is None:
        return ()
    allowed = "allowed: a list of [lo, hi] frequency pairs (Hz), 0 <= lo < hi"
    if not isinstance(raw, (list, tuple)):
        raise SceneError(f"modal.windows: {raw!r}; {allowed}")
    out = []
    for k, w in enumerate(raw):
        try:
            lo, hi = (float(x) for x in w)
        except (TypeError, ValueError):
            raise SceneError(f"modal.windows[{k}]: {w!r}; {allowed}") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo < hi):
            raise SceneError(f"modal.windows[{k}]: {w!r}; {allowed}")
        out.append((lo, hi))
    return tuple(out)


def mode_start(freqs: np.ndarray, power: np.ndarray, f0: float, n: int, floor: float) -> tuple[float, float]:
    """(damping ratio, rms) of a resonance at f0 from a power spectrum (`spectrum` normalization):
    the half-power width of the smoothed peak, and the band's power above `floor` (Parseval)."""
    df = freqs[1] - freqs[0]
    sm = smooth(power, 5)
    i = int(np.argmin(np.abs(freqs - f0)))
    top = sm[i]
    lo = i
    while lo > 0 and sm[lo] > 0.5 * top:
        lo -= 1
    hi = i
    while hi < sm.size - 1 and sm[hi] > 0.5 * top:
        hi += 1
    width = max((hi - lo) * df, 2 * df)
    zeta = float(np.clip(width / (2.0 * max(f0, df)), 2e-3, 0.3))
    band = slice(max(0, i - 3 * (i - lo) - 2), min(sm.size, i + 3 * (hi - i) + 3))
    var = 2.0 / n * float(np.sum(np.clip(power[band] - floor, 0.0, None)))
    return zeta, float(math.sqrt(max(var, 1e-30)))


# ------------------------------------------------------------------ the model


def _nest(values: dict[str, float]) -> dict[str, Any]:
    """Dotted names (`modes[0].frequency`) as a nested table, so that `get_value` reads them."""
    out: dict[str, Any] = {}
    for name, v in values.items():
        node = out
        parts = name.split(".")
        for part in parts[:-1]:
            if part.endswith("]"):
                base, i = part[:-1].split("[")
                lst = node.setdefault(base, [])
                while len(lst) <= int(i):
                    lst.append({})
                node = lst[int(i)]
            else:
                node = node.setdefault(part, {})
        node[parts[-1]] = v
    return out


@register_model
class ModalModel(SignalModel):
    """A measured series without a scene: K stochastic resonances, L lines, drift, coloured and
    white noise, one Kalman filter (module docstring)."""

    name = "modal"
    releases_gil = True  # numba nogil kernels; per-thread scratch arrays (`_scratch`)
    #: its order is chosen so that each component earns its place, and what stays is identified:
    #: over the priors (examples/modal_calibration.py, 160 draws) importance sampling covers as
    #: emcee does (0.894, 0.938, 0.912 against 0.894, 0.919, 0.900) at a tenth of the time, with
    #: the robustness bench's coverage (550 data sets, none failed)
    importance_first = True

    @classmethod
    def describes(cls, table: dict) -> bool:
        """The table has a `modal` table."""
        return isinstance(table, dict) and "modal" in table

    @classmethod
    def truth_table(cls, table: dict) -> dict:
        """The true values of a simulated series: its `modal.values` as a nested table."""
        return _nest(dict((table.get("modal") or {}).get("values") or {}))

    def __init__(self, table: dict, series: Series, gain_shapes: np.ndarray | None = None):
        """`gain_shapes` (gain terms x samples): the gain drift's basis functions in place of the
        default cosines (`gain_basis`), e.g. one given curve (`model_order.slow_reading`)."""
        self.base = copy.deepcopy(dict(table))
        self.base.setdefault("modal", {})
        self.spec = ModalSpec.from_table(self.base)
        self.series = series
        self.t = np.ascontiguousarray(series.time, dtype=float)
        self.y = np.ascontiguousarray(series.intensity, dtype=float)
        self.good = np.isfinite(self.y)
        self.n_obs = int(self.good.sum())
        self.span = float(self.t[-1] - self.t[0])
        self.dt = series.dt
        self.sd = float(np.nanstd(self.y)) or 1.0
        self.flicker_terms = flicker_terms(self.span, self.dt)  # the whole record's, kept by `head`
        if series.uniform:
            self.steps = np.array([self.span / (self.t.size - 1)])
            self.idx = np.zeros(self.t.size, dtype=np.int64)
        else:
            self.steps, self.idx = unique_steps(self.t, rtol=1e-9)
            self.steps = np.ascontiguousarray(self.steps, dtype=float)
        # a free decay's onset (`excitation_onset`): the first sample, or a blow's, whose step gets a
        # table entry of its own (the decays' fresh state is that step's process noise)
        self.onset, self.event = 0, None
        if self.spec.decays:
            self.onset = self.onset_sample(self.spec.onset)
            if self.onset > 0:
                self.steps = np.append(self.steps, self.steps[self.idx[self.onset]])
                self.idx = self.idx.copy()
                self.idx[self.onset] = self.event = self.steps.size - 1
        self._names = self.spec.names()
        self.nuisance_terms = self.spec.nuisance_terms()
        self.facts = self.data_facts()
        self._layout()
        if gain_shapes is not None:
            shapes = np.asarray(gain_shapes, dtype=float)
            if shapes.shape != self.gain_basis.shape:
                raise SceneError(
                    f"gain_shapes: shape {shapes.shape}; allowed: (modal.gain, samples) = {self.gain_basis.shape}"
                )
            self.gain_basis = np.ascontiguousarray(shapes)
        self._fixed_values = {k: float(v) for k, v in (self.base["modal"].get("values") or {}).items()}
        self._start = {k: float(v) for k, v in (self.base["modal"].get("start") or {}).items()}
        self.windows = line_windows(self.base["modal"].get("windows"))
        self._base_values: dict[str, float] | None = None
        self.start_engine()

    def start_engine(self, bins: int = 1) -> None:
        """Whittle's engine for this model's record (`whittle_engine`, its ordinates grouped `bins`
        at a time; None: the Kalman filter's), with its caches emptied: the differences' periodogram
        without lines, the leading samples that carry the level and their mean (`_whittle`)."""
        # a free decay is not stationary: the filter's engine only
        self.spectral = (
            None
            if self.spec.decays
            else whittle_engine(
                self.series,
                not bool(self.good.all()),
                bool(self.spec.gain),
                bool(np.any(self.kinds == INTEGRATED_WALK_FORM)),
                bins,
                self.spec.drifting,
            )
        )
        self._power: np.ndarray | None = None
        self._rotated: np.ndarray | None = None
        self._transform: np.ndarray | None = None
        self._full_transform: np.ndarray | None = None  # `above_passband`'s
        # the last lines' periodogram and the last density (with f(0) and the walk's step), each with
        # its key: a finite-difference step moves one parameter, so one of the two is reused
        self._lines_power: tuple[tuple, np.ndarray, np.ndarray, np.ndarray | None] | None = None
        self._line_parts: dict[tuple[float, float, float], np.ndarray] = {}
        self._density: tuple[bytes, tuple[tuple[np.ndarray, float], float, float]] | None = None
        self._level_window: int | None = None
        self._leading: tuple[int, float] | None = None

    def onset_sample(self, onset: float | None) -> int:
        """The sample of a free decay's onset `onset` (s after the first stamp: the first at or after
        it, within rounding), or, for None, the data's (`excitation_onset`)."""
        if onset is None:
            return excitation_onset(self.t, self.y)
        k = int(np.searchsorted(self.t - self.t[0], onset - 1e-9 * self.dt))
        return min(k, self.t.size - 1)

    def data_facts(self) -> DataFacts:
        """What the terms read of the data (`DataFacts`): the whole record's sd, span and step (a
        stretch of it, `head`, keeps them), the series' own Nyquist frequency, range and stamps."""
        return DataFacts(
            sd=self.sd,
            span=max(self.span, self.dt),
            dt=self.dt,
            nyquist=self.series.top,
            ymin=float(np.nanmin(self.y)),
            ymax=float(np.nanmax(self.y)),
            level=float(np.nanmean(self.y)),
            time=self.t,
            intensity=self.y,
        )

    # -------------------------------------------------------------- state-space layout
    def _layout(self) -> None:
        s = self.spec
        # the terms with states, in the state's order: the modes, the free decays, then the drift and
        # the coloured noise
        ring = float(self.t[-1] - self.t[self.onset])
        self.decay_terms = [FreeDecay(f"decays[{j}]", self.event, ring) for j in range(s.decays)]
        self.state_terms = [
            *(Oscillator(f"modes[{i}]") for i in range(s.modes)),
            *self.decay_terms,
            *self.nuisance_terms,
        ]
        self._state_names = [term.names() for term in self.state_terms]
        kinds, offsets, sizes = [], [], []
        o = 0
        for term in self.state_terms:
            for size in term.blocks(self.facts):
                kinds.append(term.block_form), offsets.append(o), sizes.append(size)
                o += size
        self.n = o
        self.kinds = np.array(kinds, dtype=np.int64)
        self.offsets = np.array(offsets, dtype=np.int64)
        lo, hi = np.zeros(max(o, 1), dtype=np.int64), np.ones(max(o, 1), dtype=np.int64)
        h = np.zeros(max(o, 1))
        for off, size in zip(offsets, sizes):
            lo[off : off + size], hi[off : off + size] = off, off + size
            h[off] = 1.0  # a mode's q, the drift's level, each Ornstein-Uhlenbeck state
        if o == 0:  # white noise only: one dummy state that never moves and is not seen
            self.kinds = np.array([WALK_FORM], dtype=np.int64)
            self.offsets = np.zeros(1, dtype=np.int64)
            h[0] = 0.0
        self.lo, self.hi, self.h = lo, hi, h
        self.block_starts, self.block_sizes = block_layout(lo, hi)
        self._nstate = max(o, 1)
        self.n_scaled = 2 * (s.modes + s.decays)  # the states the gain drift multiplies: the modes' and decays'
        self.gain_basis = gain_basis(self.t, s.gain) if s.gain else np.zeros((0, self.t.size))
        # the tables' arrays, reused between calls, one set per thread (`releases_gil`: threads
        # evaluate walkers at once); a dict by thread id stays picklable
        self._buffers: dict[tuple[int, int], tuple[np.ndarray, ...]] = {}

    def _scratch(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(phis, qs, p0, pars, mean, multiplier) of the calling thread, for this model's samples (a
        stretch of the record, `head`, shares the dict with a key of its own)."""
        key = (threading.get_ident(), self.t.size)
        out = self._buffers.get(key)
        if out is None:
            phis = np.zeros((self.steps.size, self._nstate, self._nstate))
            out = (
                phis,
                np.zeros_like(phis),
                np.zeros((self._nstate, self._nstate)),
                np.zeros((self.kinds.size, 3)),
                np.empty(self.t.size),
                np.empty(self.t.size if self.spec.gain else 0),
            )
            self._buffers[key] = out
        return out

    def value(self, values: dict[str, float], name: str) -> float:
        """A parameter's value: from `values`, else fixed by the table (`values`), else its start
        (`start`, the order search's optimum), else the first spectral guess."""
        if name in values:
            return values[name]
        if name in self._fixed_values:
            return self._fixed_values[name]
        return self._base()[name]

    def _base(self) -> dict[str, float]:
        """Every parameter's value when neither given nor fixed (computed once)."""
        if self._base_values is None:
            given = {**self._start, **self._fixed_values}
            # the spectral guesses (a least-squares sinusoid per line on a fine grid: ~1 s a call on a
            # 60,000-sample record) only where the start and the table leave a parameter without one
            covered = all(n in given for n in self._names)
            self._base_values = given if covered else {**self._spectral_guesses()[0], **given}
        return self._base_values

    def tables(
        self, values: dict[str, float], with_mean: bool = True
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, np.ndarray]:
        """(mean, phis, qs, r, P0) at `values` (the arrays are reused by the next call in this thread;
        `with_mean` False leaves the mean unfilled: Whittle's engine takes the lines in closed form)."""
        s, v = self.spec, lambda n: self.value(values, n)
        phis, qs, p0, pars, mean, _ = self._scratch()
        b = 0
        for term, names in zip(self.state_terms, self._state_names):  # each block's, in its form
            for p in term.form_parameters({n: v(n) for n in names}, self.facts):
                pars[b, : len(p)] = p
                b += 1
        if b == 0:
            pars[0, 0] = 0.0
        _fill_tables(self.kinds, pars, self.offsets, self.steps, phis, qs, p0)
        for j, term in enumerate(self.decay_terms):  # after the modes' blocks, 2 states each
            term.excite({n: v(n) for n in term.names()}, qs, p0, 2 * (s.modes + j))
        if s.lines:
            f = np.array([v(f"lines[{j}].frequency") for j in range(s.lines)])
            a = np.array([v(f"lines[{j}].amplitude") for j in range(s.lines)])
            ph = np.array([v(f"lines[{j}].phase") for j in range(s.lines)])
        else:
            f = a = ph = np.zeros(0)
        if with_mean:
            _lines_mean(self.t, float(v("level")), f, a, ph, mean)
        if s.gain:
            mean *= self.multiplier(values)
        return mean, phis, qs, float(v("noise.sigma")) ** 2 if s.white else 0.0, p0

    def multiplier(self, values: dict[str, float]) -> np.ndarray:
        """1 + g(t) at the stamps (the gain drift; module docstring), or an empty array without one
        (reused by the next call in this thread)."""
        out = self._scratch()[5]
        if self.spec.gain:
            c = np.array([self.value(values, n) for n in gain_names(self.spec.gain)])
            np.dot(c, self.gain_basis, out=out)
            out += 1.0
        return out

    def _run(self, values: dict[str, float], white: np.ndarray, lls: np.ndarray, freeze: bool = True) -> float:
        mean, phis, qs, r, p0 = self.tables(values)
        hm = self._scratch()[5]  # filled by `tables`
        if hm.size and not hm.min() > 0.0:
            return -math.inf
        if self._nstate == 2 and not hm.size:  # one mode and white noise: the scalar kernel, ~5x faster
            hold = self.hold(values) if freeze else 0
            return float(filter_two_states(self.y - mean, phis, qs, self.idx, self.h, r, p0, white, lls, hold))
        return float(
            block_filter(
                self.y - mean,
                phis,
                qs,
                self.idx,
                self.lo,
                self.hi,
                self.h,
                r,
                p0,
                self.hold(values) if freeze and not hm.size else 0,
                white,
                lls,
                hm,
                self.n_scaled,
            )
        )

    def hold(self, values: dict[str, float]) -> int:
        """Samples over which the filter's gain must stay converged before it is held
        (`block_filter`'s `freeze`): one period of the slowest mode at the shortest step, plus one;
        1 without modes (walks and Ornstein-Uhlenbeck states converge without oscillating)."""
        rings = [f"modes[{i}]" for i in range(self.spec.modes)] + [f"decays[{j}]" for j in range(self.spec.decays)]
        if not rings:
            return 1
        f = min(self.value(values, f"{c}.frequency") for c in rings)
        step = float(self.steps.min())
        if not f > 0 or not step > 0:
            return self.t.size
        return int(min(self.t.size, math.ceil(1.0 / (f * step)) + 1))

    def _sorted(self, values: dict[str, float]) -> bool:
        """Modes, lines and decays each in strictly increasing frequency (the label-switching constraint)."""
        for kind, count in (("modes", self.spec.modes), ("lines", self.spec.lines), ("decays", self.spec.decays)):
            prev = -math.inf
            for i in range(count):
                f = self.value(values, f"{kind}[{i}].frequency")
                if not f > prev:
                    return False
                prev = f
        return True

    # -------------------------------------------------------------- SignalModel
    @property
    def frequencies_searched(self) -> float:
        """M = (Nyquist - MIN_CYCLES / span) x span, the independent frequencies a mode's or line's
        frequency prior spans (at least 1): the order search's look-elsewhere term."""
        return max(1.0, (self.series.top - MIN_CYCLES / max(self.span, self.dt)) * self.span)

    def fittable(self) -> set[str]:
        return set(self._names)

    def describe(self) -> dict[str, Any]:
        return {"kind": "modal", **self.spec.table()}

    def mean(self, values: dict[str, float]) -> np.ndarray:
        """level + the lines at the data's stamps."""
        return self.tables(values)[0].copy()

    def log_likelihood(self, values: dict[str, float]) -> float:
        """The Gaussian log-likelihood: exact by the Kalman filter over every state, or Whittle's on a
        long uniform record (`spectral`); below a logger's anti-alias roll-off when the series has a
        `passband` (Whittle's on its ordinates; the filter's less `above_passband`); -inf when the
        modes' (or the lines') frequencies are not strictly increasing, or a value is outside what the
        model allows (a negative rms, a damping ratio <= 0 with noise)."""
        if not self._inside(values):
            return -math.inf
        if self.spectral is not None:
            ll = self._whittle(values)
        else:
            ll = self._run(values, np.empty(0), np.empty(0)) - self.above_passband(values)
        return ll if math.isfinite(ll) else -math.inf

    def above_passband(self, values: dict[str, float]) -> float:
        """Whittle's log-likelihood of the record's ordinates above its `passband` (0 without one),
        which the filter's exact likelihood less this leaves out: the filter's ln L of the band below
        a logger's anti-alias roll-off. Why: the filter sees the whole band, and where the filter
        plunges the model's white noise and aliased tails cannot follow it; on a decimated 40 min
        building record the order search, judging by the filter, took a 1/f noise for the white
        (the roll-off) and the white noise's sigma collapsed to 1e-6 of the floor. Whittle's
        approximation is good there: far above the drift and the slowest correlation time."""
        if self.series.passband is None:
            return 0.0
        n = self.t.size
        diff = 1 if self.spec.drifting else 0  # as the band's engine (`whittle_engine`)
        full = periodogram(n, 1, None, diff)
        kept = periodogram(n, 1, min(0.5, self.series.passband * self.series.dt), diff).c.size
        if self._full_transform is None:
            self._full_transform = full.transform(self.y)
        rest = self._full_transform
        if self.spec.lines:
            rest = rest.copy()
            for theta, psi, amp in zip(*self._line_phasors(values)):
                if amp != 0.0:
                    rest -= full.line_transform(float(theta), float(psi), float(amp))
        _, phis, qs, r, p0 = self.tables(values, with_mean=False)
        v0 = float(self.h @ p0 @ self.h) + r
        density = full.density(phis[0], qs[0], self.h, r, self.block_starts, self.block_sizes)
        if not np.all(density > 0.0):
            return math.inf
        w = full.ordinate_weights
        above = -float(dot(w[kept:], np.log(density[kept:]) + full.power(rest)[kept:] / density[kept:]))
        above -= float(w[kept:].sum()) * _LOG_2PI
        if diff:  # the end-to-end jump's shared term of the whole band less the band's (`shared_jump`)
            inverse, x, tau2 = w / density, full.rotated(rest), 2.0 * v0 / full.m
            above += shared_jump(inverse, x, tau2)[0] - shared_jump(inverse[:kept], x[:kept], tau2)[0]
        return above

    def exact_log_likelihood(self, values: dict[str, float]) -> float:
        """The Kalman filter's exact log-likelihood (less the ordinates above a `passband`:
        `above_passband`), whichever engine `log_likelihood` uses: what
        the order search compares (`model_order.fit_order`), so that orders fitted by Whittle's
        likelihood and orders only the filter can run (a gain drift) are judged alike. On a record
        with a trend Whittle's error depends on the model by thousands (an hour at 200 Hz with a
        quadratic drift: 3,000 without a walk, 1,200 with one), which the filter does not share."""
        if not self._inside(values):
            return -math.inf
        ll = self._run(values, np.empty(0), np.empty(0)) - self.above_passband(values)
        return ll if math.isfinite(ll) else -math.inf

    def _inside(self, values: dict[str, float]) -> bool:
        """Modes and lines sorted by frequency, every value finite and where the model allows it."""
        if not self._sorted(values):
            return False
        for n in self._names:
            val = self.value(values, n)
            if not math.isfinite(val):
                return False
            if n.endswith(("frequency", "damping_ratio", "time")) and not val > 0:
                return False
            if (n.endswith(("rms", "sigma", "rate")) or n.startswith("decays[")) and val < 0:
                return False
        return True

    def _spectra(self, values: dict[str, float]) -> tuple[np.ndarray | None, np.ndarray, np.ndarray | None]:
        """(the transform less the lines, or None without lines; its periodogram; its `rotated`
        part, None on the record's own periodogram), each reduced to the engine's groups but the
        transform: the record's once, the lines' in closed form (`_rest_without_lines`)."""
        sp = self.spectral
        if self.spec.lines:
            if self._transform is None:
                self._transform = sp.transform(self.y)
            return self._rest_without_lines(*self._line_phasors(values))
        if self._power is None:  # a constant mean: computed once
            spec = sp.transform(self.y)
            self._power = sp.reduce(sp.power(spec))
            self._rotated = sp.reduce(sp.rotated(spec)) if sp.differences else None
        return None, self._power, self._rotated

    def _whittle(self, values: dict[str, float]) -> float:
        """Whittle's log-likelihood of the record, or of its differences with the end-to-end jump's
        shared term (`vibinverse.engines.whittle.shared_jump`), and the level's share
        (`level_term`: the mean residual of the leading samples that carry it)."""
        _, phis, qs, r, p0 = self.tables(values, with_mean=False)
        _, power, rotated = self._spectra(values)
        if self.spec.lines:
            theta, psi, amp = self._line_phasors(values)
        blocks = (self.block_starts, self.block_sizes)
        v0 = float(self.h @ p0 @ self.h) + r  # the stationary part's variance (the walk's P0 is 0)
        key = np.concatenate((phis[0].ravel(), qs[0].ravel(), (r, v0))).tobytes()
        cached = self._density
        if cached is not None and cached[0] == key:
            weights, f0, q = cached[1]
        else:
            density = self.spectral.density(phis[0], qs[0], self.h, r, *blocks)
            weights = self.spectral.weights(density)
            f0 = self.spectral.zero_density(phis[0], qs[0], self.h, r, *blocks)
            q = walk_step_variance(phis[0], qs[0], self.h, *blocks)
            self._density = (key, (weights, f0, q))
        ll = self.spectral.weighted(power, weights)
        if rotated is not None and math.isfinite(ll):
            ll += shared_jump(weights[0], rotated, 2.0 * v0 / self.spectral.m)[0]
        if self._level_window is None:  # fixed at the first values seen: the likelihood stays smooth
            self._level_window = level_window(f0, q, self.t.size)
        k = self._level_window
        if self.spec.lines:
            e = self._leading_mean(k) - self.value(values, "level") - lines_sum(k, theta, psi, amp) / k
        else:  # the mean is the level: the window's mean of y once
            e = self._leading_mean(k) - self.value(values, "level")
        return ll + level_term(e, k, f0, v0, q)

    def slope(self, values: dict[str, float], names: list[str]) -> dict[str, float] | None:
        """Whittle's gradient (`whittle_gradient`) when Whittle's engine runs; None otherwise."""
        return None if self.spectral is None else self.whittle_gradient(values, names)

    def whittle_gradient(self, values: dict[str, float], names: list[str] | None = None) -> dict[str, float]:
        """d ln L / d value of Whittle's log-likelihood (`_whittle`) at `values` for each of `names`
        (default: every parameter), from its linearization: d ln L = sum_j w_j (I_j / f_j^2 - 1 / f_j)
        df_j - sum_j w_j / f_j dI_j, plus the level term's change. Analytic: df_j in each table entry of
        a block (`Periodogram.block_gradient`, one pass over the ordinates per block a parameter moves,
        shared by its parameters) and dI_j = 2 Re(X_j* dX_j) / m in a line's frequency, amplitude and
        phase (`Periodogram.line_gradient`, one pass per line). Still forward steps of 1e-7 of the
        value's scale: the small tables' entries in a state parameter (its own term's blocks refilled
        alone, `_term_tables`), r and the stationary variance (the end-to-end jump's term), and the
        level term. The jump's term (`shared_jump`) adds to each group's slope and to the lines'."""
        if self.spectral is None:
            raise Unsupported("the gradient is of Whittle's likelihood (a long steady record)")
        sp, h = self.spectral, self.h
        starts, sizes = self.block_starts, self.block_sizes
        names = list(self._names) if names is None else list(names)
        _, phis, qs, r, p0 = self.tables(values, with_mean=False)
        phi, q, p0 = phis[0].copy(), qs[0].copy(), p0.copy()
        rest, power, rotated = self._spectra(values)
        if self.spec.lines:
            theta, psi, amp = self._line_phasors(values)
        else:
            theta = psi = amp = np.zeros(0)
        v0 = float(h @ p0 @ h) + r
        density = sp.density(phi, q, h, r, starts, sizes)
        inverse = sp.group_weights / density
        slope = inverse * (power / density - 1.0)  # d ln L / d f_j
        jump_b = 0.0  # the shared jump's dC/db (`shared_jump`), and d ln L / d v0 through tau^2 = 2 v0 / m
        slope_ends = 0.0
        if rotated is not None:
            _, d_a, jump_b, d_tau2 = shared_jump(inverse, rotated, 2.0 * v0 / sp.m)
            slope = slope - 2.0 * (inverse / density) * (d_a + jump_b * rotated)
            slope_ends = d_tau2 * 2.0 / sp.m
        gain = sp.group_c if sp.differences else np.ones(density.size)  # d f_j / d r
        f0 = sp.zero_density(phi, q, h, r, starts, sizes)
        walk = walk_step_variance(phi, q, h, starts, sizes)
        if self._level_window is None:
            self._level_window = level_window(f0, walk, self.t.size)
        k = self._level_window

        def level(phi_: np.ndarray, q_: np.ndarray, p0_: np.ndarray, r_: float, e: float) -> float:
            v = float(h @ p0_ @ h) + r_
            f0_ = sp.zero_density(phi_, q_, h, r_, starts, sizes)
            return level_term(e, k, f0_, v, walk_step_variance(phi_, q_, h, starts, sizes))

        lines_at = lines_sum(k, theta, psi, amp) / k if self.spec.lines else 0.0
        e0 = self._leading_mean(k) - self.value(values, "level") - lines_at
        base_level = level_term(e0, k, f0, v0, walk)
        line_of = {
            f"lines[{j}].{field}": (j, i)
            for j in range(self.spec.lines)
            for i, field in enumerate(("frequency", "amplitude", "phase"))
        }
        # what every parameter's slope shares: sum_j slope_j df_j / d r (v0 moves the jump's term alone)
        slope_r = dot(slope, np.ascontiguousarray(gain))
        term_of = {n: i for i, term_names in enumerate(self._state_names) for n in term_names}
        blocks: dict[int, np.ndarray] = {}  # sum_j slope_j df_j / d entry, per block

        def entries(phi_: np.ndarray, q_: np.ndarray, b: int) -> np.ndarray:
            o = int(starts[b])
            if sizes[b] == 1:
                return np.array([phi_[o, o], q_[o, o]])
            a, c = phi_[o : o + 2, o : o + 2], q_[o : o + 2, o : o + 2]
            return np.array([a[0, 0], a[0, 1], a[1, 0], a[1, 1], c[0, 0], c[0, 1], c[1, 1]])

        if rest is not None:
            on_ordinates = sp.ordinate_inverse(density, inverse)
            weighted_re = on_ordinates * rest.real
            weighted_im = on_ordinates * rest.imag
            if jump_b:  # the jump's term: dC/dx_j = jump_b 2 w_j / f_j, x_j = Re(X_j e^{-i w_j}) / sqrt(m)
                share = -jump_b * math.sqrt(sp.m) * on_ordinates
                weighted_re = weighted_re + share * sp.cw
                weighted_im = weighted_im + share * sp.sw
            weighted_re, weighted_im = np.ascontiguousarray(weighted_re), np.ascontiguousarray(weighted_im)
            grid = (self.t[-1] - self.t[0]) / (self.t.size - 1)  # `_line_phasors`' theta = 2 pi f grid
        lines: dict[int, np.ndarray] = {}  # d ln L / d (amp, theta / amp, psi / amp), per line
        out: dict[str, float] = {}
        for name in names:
            v = self.value(values, name)
            # a phase's and the level's scale is not their value (which may be 0); a frequency's is
            # at most a Fourier bin (a line's ln L curves on that scale: 1e-7 of 7.3 Hz over 400 s
            # was 0.5 % off its slope)
            floor = 1.0 if name.endswith(".phase") else self.sd if name == "level" else 0.0
            step = 1e-7 * max(abs(v), floor) or 1e-300
            if name.endswith(".frequency"):
                step = 1e-6 * min(abs(v), 1.0 / max(self.span, self.dt)) or 1e-300
            moved = {**values, name: v + step}
            if name == "level":
                out[name] = (level_term(e0 - step, k, f0, v0, walk) - base_level) / step
            elif name in line_of:
                j, field = line_of[name]
                if j not in lines:  # -sum_j w_j / f_j dI_j with dX = -d(line's transform)
                    lines[j] = (2.0 / sp.m) * sp.line_gradient(float(theta[j]), float(psi[j]), weighted_re, weighted_im)
                g_amp, g_theta, g_psi = lines[j]
                if field == 1:
                    d_ll = g_amp
                elif field == 2:
                    d_ll = amp[j] * g_psi
                else:  # theta = 2 pi f grid, psi = 2 pi f t_0 + phase
                    d_ll = amp[j] * 2.0 * math.pi * (g_theta * grid + g_psi * self.t[0])
                th, ps, am = self._line_phasors(moved)
                e1 = self._leading_mean(k) - self.value(values, "level") - lines_sum(k, th, ps, am) / k
                out[name] = d_ll + (level_term(e1, k, f0, v0, walk) - base_level) / step
            else:
                if name in term_of:  # its own term's blocks
                    phi1, q1, p01, moves = self._term_tables(term_of[name], moved, phi, q, p0)
                    r1 = r
                elif name == "noise.sigma":  # r alone
                    phi1, q1, p01, moves = phi, q, p0, range(0)
                    r1 = float(v + step) ** 2 if self.spec.white else 0.0
                else:  # anything else: every block's tables
                    _, phis1, qs1, r1, p01 = self.tables(moved, with_mean=False)
                    phi1, q1, p01, moves = phis1[0].copy(), qs1[0].copy(), p01.copy(), range(starts.size)
                changed = (r1 - r) * slope_r + (float(h @ p01 @ h) + r1 - v0) * slope_ends
                for b in moves:
                    d = entries(phi1, q1, b) - entries(phi, q, b)
                    if not d.any():
                        continue
                    if b not in blocks:
                        blocks[b] = sp.block_gradient(phi, q, h, starts[b], sizes[b], slope)
                    changed += float(blocks[b] @ d)
                out[name] = (changed + level(phi1, q1, p01, r1, e0) - base_level) / step
        return out

    def _term_tables(
        self, term: int, values: dict[str, float], phi: np.ndarray, q: np.ndarray, p0: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, range]:
        """(Phi, Q, P0) of the first step (`tables`' phis[0], qs[0], P0) with state term `term`'s
        blocks refilled at `values` and the others' entries kept from (phi, q, p0) (copies), and
        the range of its blocks: what `tables` gives when only that term's values move."""
        first = sum(len(t.blocks(self.facts)) for t in self.state_terms[:term])
        forms = self.state_terms[term].form_parameters(
            {n: self.value(values, n) for n in self._state_names[term]}, self.facts
        )
        count = len(forms)
        if not count:
            return phi, q, p0, range(first, first)
        pars = np.zeros((count, 3))
        for b, p in enumerate(forms):
            pars[b, : len(p)] = p
        lo = int(self.offsets[first])
        hi = int(self.offsets[first + count - 1] + self.block_sizes[first + count - 1])
        phis, qs, p0s = np.zeros((1, hi - lo, hi - lo)), np.zeros((1, hi - lo, hi - lo)), np.zeros((hi - lo, hi - lo))
        offsets = np.ascontiguousarray(self.offsets[first : first + count] - lo)
        kinds = np.ascontiguousarray(self.kinds[first : first + count])
        _fill_tables(kinds, pars, offsets, np.ascontiguousarray(self.steps[:1]), phis, qs, p0s)
        phi1, q1, p01 = phi.copy(), q.copy(), p0.copy()
        phi1[lo:hi, lo:hi], q1[lo:hi, lo:hi], p01[lo:hi, lo:hi] = phis[0], qs[0], p0s
        return phi1, q1, p01, range(first, first + count)

    def _rest_without_lines(
        self, theta: np.ndarray, psi: np.ndarray, amp: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """(transform, periodogram, `rotated` part or None on the record's own periodogram) of the
        record less its lines, the last two reduced to the engine's groups: each line's transform kept with
        its values (a finite-difference step moves one line; the others are reused), the last
        result with all of them. The caches are replaced whole, never changed in place: threads
        that evaluate walkers at once may recompute, never mix."""
        keys = tuple(zip(theta.tolist(), psi.tolist(), amp.tolist()))
        cached = self._lines_power
        if cached is not None and cached[0] == keys:
            return cached[2], cached[1], cached[3]
        parts = dict(self._line_parts)
        rest = self._transform.copy()
        for key in keys:
            if key[2] == 0.0:  # a line held at zero amplitude (a detection test's null) adds nothing
                continue
            part = parts.get(key)
            if part is None:
                part = parts[key] = self.spectral.line_transform(*key)
            rest -= part
        # kept: this call's lines and the last call's (a step and the point it steps from)
        last = cached[0] if cached is not None else ()
        self._line_parts = {k: parts[k] for k in (*last, *keys) if k in parts}
        sp = self.spectral
        power = sp.reduce(sp.power(rest))
        rotated = sp.reduce(sp.rotated(rest)) if sp.differences else None
        self._lines_power = (keys, power, rest, rotated)
        return rest, power, rotated

    def _line_phasors(self, values: dict[str, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The lines on the record's grid, a cos(theta k + psi): theta = 2 pi f dt radians per sample
        (dt the grid's step from the first to the last stamp), psi = 2 pi f t_0 + phase."""
        n = self.t.size
        step = (self.t[-1] - self.t[0]) / (n - 1)
        idx = range(self.spec.lines)
        f = np.array([self.value(values, f"lines[{j}].frequency") for j in idx])
        amp = np.array([self.value(values, f"lines[{j}].amplitude") for j in idx])
        ph = np.array([self.value(values, f"lines[{j}].phase") for j in idx])
        w = 2.0 * math.pi * f
        return w * step, w * self.t[0] + ph, amp

    def _leading_mean(self, k: int) -> float:
        """The mean of the first k samples (kept for the last k asked)."""
        if self._leading is None or self._leading[0] != k:
            self._leading = (k, float(np.mean(self.y[:k])))
        return self._leading[1]

    def head(self, n: int) -> ModalModel:
        """The same model on the first n samples: what is fixed by the whole record stays (the 1/f
        term's states and lowest corner and the gain drift's cosines span the whole record, the values of
        parameters that are not free come from its spectrum)."""
        self._base()  # the record's own, before the cut
        out = copy.copy(self)
        out.series = self.series.head(n)
        out.t, out.y, out.good, out.idx = self.t[:n], self.y[:n], self.good[:n], self.idx[:n]
        out.n_obs = int(out.good.sum())
        out.gain_basis = np.ascontiguousarray(self.gain_basis[:, :n])
        out.facts = out.data_facts()
        out.start_engine()
        return out

    def pointwise_log_likelihood(self, values: dict[str, float]) -> np.ndarray:
        """Each sample's one-step predictive log density (NaN at gaps); nansum = log_likelihood."""
        out = np.empty(self.t.size)
        self._run(values, np.empty(0), out)
        return out

    def residuals(self, values: dict[str, float]) -> np.ndarray:
        """Standardized innovations (NaN at gaps): independent N(0, 1) when the model fits."""
        out = np.empty(self.t.size)
        self._run(values, out, np.empty(0))
        return out

    def filtered(self, values: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
        """(`residuals`, `pointwise_log_likelihood`) from one pass of the filter."""
        white, lls = np.empty(self.t.size), np.empty(self.t.size)
        self._run(values, white, lls)
        return white, lls

    def replicate(self, values: dict[str, float], rng: np.random.Generator) -> np.ndarray:
        """A draw of the model at the data's stamps (states started in their stationary law, the
        walk at 0), plus the white noise; NaN at the data's gaps. Compiled, one pass."""
        mean, phis, qs, r, p0 = self.tables(values)
        hm = self._scratch()[5].copy()
        out = simulate_blocks(phis, qs, self.idx, self.lo, self.hi, self.h, r, p0, rng, hm=hm, nscaled=self.n_scaled)
        out += mean
        out[~self.good] = np.nan
        return out

    def units(self, name: str) -> tuple[str, str]:
        """Intensity units for rms values, amplitudes, the level and the sensor noise;
        intensity / sqrt(s) for the drift rate (intensity / s^1.5 integrated); s for `ar.time`."""
        iu = intensity_units(self.series)
        # the model's nuisance terms answer for their parameters; a name the model lacks, the first
        # registered drift or coloured noise that has it
        kinds = (cls() for cls in (*DRIFT_TERMS.values(), *NOISE_TERMS.values()) if cls is not None)
        for term in (*self.decay_terms, *self.nuisance_terms, *kinds):
            if name in term.names():
                return term.units(name, iu)
        if name.endswith(".rms"):
            return iu, "mode stationary RMS"
        if name.endswith(".amplitude"):
            return iu, "line amplitude"
        if name == "level":
            return iu, "level at the first sample"
        if name.startswith("gain.a"):
            return "1", f"gain drift, cosine of {int(name[6:]) / 2:g} cycles per record"
        return parameter_units(name, iu)

    def default_priors(self) -> dict[str, Prior]:
        """Frequencies uniform from MIN_CYCLES (1) cycle per record (the least `check_fit` accepts)
        to Nyquist; damping ratios log-uniform 1e-4..0.9; mode rms log-uniform sd x (1e-4, 10); line
        amplitudes uniform 0..3 sd (a line whose start lies in one of the table's `windows`: its
        frequency uniform over that window, within the same limits); phases uniform over a period
        centred on the start's (the order search's optimum, else the first spectral guess); level
        uniform over the data's range widened by it on each side; noise.sigma and the coloured noise's rms log-uniform
        sd x (1e-6, 10); ar.time log-uniform (dt / 5, span); flicker.corner log-uniform from
        FLICKER_LOWEST_CORNER (10) cycles per record to Nyquist; drift.rate log-uniform
        sd / sqrt(span) x (1e-5, 30); the gain drift's coefficients uniform (-0.5, 0.5).
        (sd: the data's standard deviation.)"""
        sd, span, nyq = self.sd, max(self.span, self.dt), self.series.top
        lo = MIN_CYCLES / span * (1.0 + 1e-9)  # past rounding (`check_resolves`)
        ymin, ymax = float(np.nanmin(self.y)), float(np.nanmax(self.y))
        rng = ymax - ymin
        out: dict[str, Prior] = {"level": Prior("uniform", (ymin - rng, ymax + rng))}
        for i in range(self.spec.modes):
            out[f"modes[{i}].frequency"] = Prior("uniform", (lo, nyq))
            out[f"modes[{i}].damping_ratio"] = Prior("loguniform", (1e-4, 0.9))
            out[f"modes[{i}].rms"] = Prior("loguniform", (1e-4 * sd, 10.0 * sd))
        for j in range(self.spec.lines):
            out[f"lines[{j}].frequency"] = Prior("uniform", self.line_window(j, (lo, nyq)))
            out[f"lines[{j}].amplitude"] = Prior("uniform", (0.0, 3.0 * sd))
            # a full period, centred on the start's phase (the order search's optimum, else the first
            # spectral guess): the same prior on the circle, but the MAP is not pinned at a window's
            # edge by the logit's Jacobian (in 8 %
            # of the bench's clean records the phase lay within 2 sd of +-pi, and the frequency,
            # correlated with it at -0.87, came out with intervals 11 % narrow, coverage 0.84)
            centre = self.value({}, f"lines[{j}].phase")  # not wrapped: the start stays at the centre
            centre = centre if math.isfinite(centre) else 0.0
            out[f"lines[{j}].phase"] = Prior("uniform", (centre - math.pi, centre + math.pi))
        for term in (*self.decay_terms, *self.nuisance_terms):
            out.update(term.priors(self.facts))
        for n in gain_names(self.spec.gain):
            out[n] = Prior("uniform", (-GAIN_LIMIT, GAIN_LIMIT))
        if self.spec.white:
            out["noise.sigma"] = Prior("loguniform", (1e-6 * sd, 10.0 * sd))
        return out

    def unused_windows(self) -> list[int]:
        """The indices of the table's `windows` that hold no line's start: they narrow nothing."""
        starts = [self.value({}, f"lines[{j}].frequency") for j in range(self.spec.lines)] if self.windows else []
        return [k for k, (lo, hi) in enumerate(self.windows) if not any(lo <= f <= hi for f in starts)]

    def line_window(self, j: int, limits: tuple[float, float]) -> tuple[float, float]:
        """Line `j`'s frequency window: the first of the table's `windows` that holds its start,
        within `limits`; else `limits`."""
        f = self.value({}, f"lines[{j}].frequency") if self.windows else math.nan
        for lo, hi in self.windows:
            a, b = max(lo, limits[0]), min(hi, limits[1])
            if lo <= f <= hi and a < b:
                return a, b
        return limits

    def _spectral_guesses(self) -> list[dict[str, float]]:
        """Starting values of every parameter from the periodogram: the K + L strongest peaks of
        the smoothed spectrum; the lines at the sharpest of them (highest raw bin over its smoothed
        neighbourhood), the modes at the others (half-power width and band power); a second start
        with the roles of the sharpest peaks exchanged."""
        s = self.spec
        freqs, power = spectrum(self.y, self.steps[0] if self.steps.size == 1 else self.dt, self.t)
        nyq, lo = self.series.top, MIN_CYCLES / max(self.span, self.dt) * (1.0 + 1e-9)  # the prior's edge
        n = self.n_obs
        floor = (
            float(np.median(power[(freqs > 0.5 * nyq) & (freqs <= nyq)])) / math.log(2.0)
            if np.any((freqs > 0.5 * nyq) & (freqs <= nyq))
            else float(np.median(power))
        )
        width = max(3, round(0.002 * freqs.size) | 1)
        # from the first Fourier bin (1 / (N dt): a cycle in N dt, just under one in the span (N - 1) dt)
        first = min(lo, float(freqs[0]))
        # a drift, a gain drift or a coloured noise puts its power at low frequencies, the first
        # bin's above all: the peaks are searched over its background there (`background`)
        ranked = power / background(freqs, power) if s.drifting or s.coloured or s.gain else power
        need = s.modes + s.lines + s.decays
        peaks = spectral_peaks(
            freqs, ranked, (first, nyq * 0.999), width, separation=3 * width * (freqs[1] - freqs[0]), limit=need
        )
        while len(peaks) < need:  # fewer peaks than components: spread the rest over the band
            peaks.append((lo + (nyq - lo) * (len(peaks) + 1) / (need + 1), 1.0))
        picked = [f for f, _ in peaks[:need]]
        sharp = []
        for f in picked:
            i = int(np.argmin(np.abs(freqs - f)))
            win = slice(max(0, i - width), i + width + 1)
            sharp.append(float(power[win].max() / max(np.mean(power[win]), 1e-300)))
        order = list(np.argsort(sharp)[::-1])
        assignments = [order]
        if s.lines and s.modes:
            assignments.append(order[s.lines :] + order[: s.lines])
        base = {
            "level": float(np.nanmean(self.y[: max(16, self.t.size // 50)]))
            if s.drifting
            else float(np.nanmean(self.y)),
            "noise.sigma": math.sqrt(max(floor, 1e-30 * self.sd**2)),
            **{k: x for term in self.nuisance_terms for k, x in term.starts(self.facts).items()},
            **dict(zip(gain_names(s.gain), map(float, self.gain_start()))),
        }
        out = []
        from vibinverse.spectrum import sinusoid, strongest_sinusoid

        y0 = self.y - np.nanmean(self.y)
        for assign in assignments:
            g = dict(base)
            line_f = sorted(picked[i] for i in assign[: s.lines])
            # the first bin lies under the prior
            mode_f = sorted(max(picked[i], lo) for i in assign[s.lines : s.lines + s.modes])
            for i, f in enumerate(mode_f):
                zeta, rms = mode_start(freqs, power, f, n, floor)
                g[f"modes[{i}].frequency"], g[f"modes[{i}].damping_ratio"], g[f"modes[{i}].rms"] = f, zeta, rms
            for j, f in enumerate(sorted(max(picked[i], lo) for i in assign[s.lines + s.modes :])):
                g.update(self.decay_start(j, f, *mode_start(freqs, power, f, n, floor)))
            for j, f in enumerate(line_f):
                i = int(np.argmin(np.abs(freqs - f)))  # the highest raw bin near the smoothed peak
                i = max(i - width, 0) + int(np.argmax(power[max(i - width, 0) : i + width + 1]))
                fine = np.linspace(max(freqs[max(i - 1, 0)], lo), max(freqs[min(i + 1, freqs.size - 1)], lo), 21)
                best = strongest_sinusoid(self.t, y0, fine)
                a, ph, _ = sinusoid(self.t, y0, best)
                g[f"lines[{j}].frequency"], g[f"lines[{j}].amplitude"], g[f"lines[{j}].phase"] = float(best), a, ph
            out.append({k: g[k] for k in self._names})
        return out

    def decay_start(self, j: int, f: float, zeta: float, rms: float) -> dict[str, float]:
        """Decay j's start from a resonance's reading of its peak (f, zeta, the record's RMS there:
        `ring_start`)."""
        return ring_start(f"decays[{j}]", f, zeta, rms, float(self.t[-1] - self.t[self.onset]), max(self.span, self.dt))

    def gain_start(self, terms: int | None = None) -> np.ndarray:
        """Starting coefficients of a gain drift of `terms` cosines (default: the model's): the
        least-squares fit of the cosines (and a constant, dropped) to y / mean(y) - 1, which keeps
        the slow relative change of the level (the projection on J smooth cosines averages the
        vibration out); zeros when the level is not well above the data's sd (a relative change
        of a level near 0 means nothing), clipped inside the prior."""
        terms = self.spec.gain if terms is None else terms
        level = float(np.nanmean(self.y))
        if not terms or not abs(level) > self.sd:
            return np.zeros(terms)
        basis = gain_basis(self.t, terms)[:, self.good]
        design = np.vstack([np.ones(basis.shape[1]), basis]).T
        coef = np.linalg.lstsq(design, self.y[self.good] / level - 1.0, rcond=None)[0][1:]
        return np.clip(coef, -0.9 * GAIN_LIMIT, 0.9 * GAIN_LIMIT).astype(float)

    def guesses(self, bounds: dict[str, tuple[float, float]]) -> list[dict[str, float]]:
        """The table's `start` first (the order search's optimum), else the spectral starts
        (`_spectral_guesses`)."""
        if self._start:
            return [{**{n: self.value({}, n) for n in self._names}, **self._start}]
        return self._spectral_guesses()

    def line_tests(self, values: dict[str, float], free: list[str]) -> list[LineTest]:
        """Each line (its amplitude to 0), each mode (its rms to 0) and each free decay (its amplitude
        to 0), with the parameters near it (`near_parameters`)."""
        out = []
        for j in range(self.spec.lines):
            f = f"lines[{j}].frequency"
            near = self.near_parameters(values, f"lines[{j}]")
            hz = self.value(values, f)
            out.append(
                LineTest(f"line_{j}", {f"lines[{j}].amplitude": 0.0}, f if f in free else None, True, near, hz=hz)
            )
        # (kind, test label, the scale its null sets to 0, count, a free decay's measured decay rate)
        rings = (
            ("modes", "mode", "rms", self.spec.modes, False),
            ("decays", "decay", "amplitude", self.spec.decays, True),
        )
        for kind, label, scale, count, ring in rings:
            for i in range(count):
                c = f"{kind}[{i}]"
                f = f"{c}.frequency"
                damping, hz = self.value(values, f"{c}.damping_ratio"), self.value(values, f)
                near = self.near_parameters(values, c)
                null = {f"{c}.{scale}": 0.0}
                test = LineTest(
                    f"{label}_{i}", null, f if f in free else None, near=near, damping=damping, hz=hz, ring=ring
                )
                out.append(test)
        return out

    def near_parameters(self, values: dict[str, float], component: str) -> tuple[str, ...]:
        """The parameters that can take back `component`'s power (`"lines[j]"` or `"modes[i]"`) when
        it is removed: its own, those of every mode and line whose band comes within NEAR_REACH_BINS
        Fourier bins plus NEAR_REACH_WIDTHS half-power half-widths (zeta f, of either) of it, and
        every parameter that is not a mode's or a line's (level, noise, drift, gain: broadband)."""
        v = lambda n: self.value(values, n)
        width = lambda c: v(f"{c}.damping_ratio") * v(f"{c}.frequency") if c.startswith(("modes", "decays")) else 0.0
        f0, w0 = v(f"{component}.frequency"), width(component)
        bins = NEAR_REACH_BINS / max(self.span, self.dt)
        near = [
            c
            for c in (
                *(f"modes[{i}]" for i in range(self.spec.modes)),
                *(f"lines[{j}]" for j in range(self.spec.lines)),
                *(f"decays[{j}]" for j in range(self.spec.decays)),
            )
            if abs(v(f"{c}.frequency") - f0) <= bins + NEAR_REACH_WIDTHS * max(w0, width(c))
        ]
        rings = ("modes[", "lines[", "decays[")
        return tuple(n for n in self._names if not n.startswith(rings) or n.split(".")[0] in near)

    def fisher(self, values: dict[str, float], names: list[str]) -> np.ndarray:
        """The observed information -d^2 log L / d theta^2 at `values` (its expectation is the
        Fisher information), by central finite differences of the log-likelihood (the filter's
        exact one, or Whittle's where the posterior uses it): a first
        pass gives each parameter's curvature with a step of 1e-4 of its scale, the second uses a
        step of 0.1 / sqrt(curvature) (a tenth of the parameter's sd), so that every step is small
        against the likelihood's width whatever the units."""
        v0 = {**{n: self.value(values, n) for n in self._names}, **values}

        def scale(n: str) -> float:
            if n == "level":
                return self.sd
            return max(1.0 if n.endswith("phase") else abs(v0[n]), 1e-6 * self.sd)

        def log_likelihood(d: dict[str, float]) -> float:
            if self.spectral is not None:  # the likelihood the posterior uses
                return self._whittle({**v0, **d})
            return self._run({**v0, **d}, np.empty(0), np.empty(0), freeze=False)

        return observed_information(
            log_likelihood,
            v0,
            names,
            scale,
            lambda n: not n.endswith("phase") and n != "level",
        )

    # -------------------------------------------------------------- what the order search reads
    def components(self, values: dict[str, float]) -> list[dict[str, Any]]:
        """The fitted components at `values`, JSON-able: the level, each mode, each line (with
        `harmonic_of` the index of the line it is a harmonic of, within one resolution bin
        1 / span of a multiple, else None), the drift, the coloured and the white noise."""
        v = lambda n: float(self.value(values, n))
        s = self.spec
        out: list[dict[str, Any]] = [{"kind": "level", "level": v("level")}]
        for i in range(s.modes):
            out.append(
                {
                    "kind": "mode",
                    "index": i,
                    "frequency": v(f"modes[{i}].frequency"),
                    "damping_ratio": v(f"modes[{i}].damping_ratio"),
                    "rms": v(f"modes[{i}].rms"),
                }
            )
        freqs = [v(f"lines[{j}].frequency") for j in range(s.lines)]
        for j in range(s.lines):
            source, multiple = harmonic_of(freqs, j, 1.0 / max(self.span, self.dt))
            out.append(
                {
                    "kind": "line",
                    "index": j,
                    "frequency": freqs[j],
                    "amplitude": v(f"lines[{j}].amplitude"),
                    "phase": v(f"lines[{j}].phase"),
                    "harmonic_of": source,
                    "harmonic": multiple,
                }
            )
        onset = float(self.t[self.onset] - self.t[0])
        for j, term in enumerate(self.decay_terms):
            out.append({**term.component({n: v(n) for n in term.names()}, self.facts), "index": j, "onset": onset})
        for term in self.nuisance_terms:
            out.append(term.component({n: v(n) for n in term.names()}, self.facts))
        if s.gain:
            g = self.multiplier(values) - 1.0
            out.append(
                {
                    "kind": "gain drift",
                    "terms": s.gain,
                    "largest": float(np.max(np.abs(g))),
                    "coefficients": [v(n) for n in gain_names(s.gain)],
                }
            )
        if s.white:
            out.append({"kind": "white noise", "sigma": v("noise.sigma")})
        return out


def harmonic_of(freqs: list[float], j: int, resolution: float) -> tuple[int | None, int | None]:
    """(index of the lowest line whose multiple m >= 2 lies within `resolution` of line j, m), or
    (None, None)."""
    for i, f0 in enumerate(freqs):
        if i == j or f0 <= 0 or freqs[j] < 1.5 * f0:
            continue
        m = round(freqs[j] / f0)
        if m >= 2 and abs(freqs[j] - m * f0) <= resolution:
            return i, m
    return None, None

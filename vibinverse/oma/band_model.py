"""The multi-channel frequency-domain likelihood of one band (Au's Bayesian FFT; Whittle for vectors).

In a band [lo, hi] that holds M modes, the Fourier ordinates Y_j of the C response channels
(`vibinverse.oma.spectral_matrix`) are independent complex Gaussian vectors with

    E[Y_j Y_j^H] = E_j = sum_m g_m(f_j) phi_m phi_m^T + diag(n_c (f_j / f_centre)^beta_c) + B_j,

phi_m the mode's (real, classically damped) shape, n_c (f / f_centre)^beta_c channel c's in-band
noise (a power law: coloured sensor noise and drift over a band of +-30 %), B_j the in-band tails of
the modes fitted in the other bands (held fixed; without them a tail, correlated across channels, is
mistaken for a broad mode), and g_m the modal response's
spectral density: the `vibinverse.terms.resonance.Oscillator` term's PSD (a white-noise-driven
resonance, 2 kappa / |w^2 - W^2 + 2 i zeta w W|^2, kappa = 4 zeta w^3) times the modal force's
spectrum s_m (f / f_m)^alpha_m (a power law across the band: coloured forcing), and times W^(2p)
for a channel that measures velocity (p = 1) or acceleration (p = 2)
(`QUANTITY_POWER`). Modal forces of different modes are taken as uncorrelated. Then

    ln L = - sum_j [ C ln pi + ln det E_j + Y_j^H E_j^{-1} Y_j ],

and with R_j = Re(E_j^{-1} - E_j^{-1} Y_j Y_j^H E_j^{-1}), d ln L = - sum_j tr(R_j dE_j): the gradient in
closed form, one batched C x C inverse per ordinate and evaluation.

Parameters (the optimizer's x, all unconstrained but for bounds): per mode ln f, ln zeta, ln s, alpha; per
mode the shape's C - 1 free components (`BandLayout.reference`: one component held at 1 fixes the
scale and sign, s carries the scale); per channel ln n and beta. The reported shape is phi / |phi|, signed so
that its largest-magnitude component is positive.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from vibinverse.engines.kalman import njit
from vibinverse.terms.base import DataFacts
from vibinverse.terms.resonance import Oscillator

#: the power of W = 2 pi f by which a measured quantity's spectrum exceeds the displacement's
QUANTITY_POWER: Mapping[str, int] = {"displacement": 0, "velocity": 1, "acceleration": 2}

#: units (lower case, spaces removed) read as each measured quantity; anything else is acceleration
#: unless the caller says otherwise
QUANTITY_OF_UNITS = {
    "m": "displacement",
    "mm": "displacement",
    "um": "displacement",
    "µm": "displacement",
    "in": "displacement",
    "m/s": "velocity",
    "mm/s": "velocity",
    "in/s": "velocity",
}


def quantity_of(units: tuple[str | None, ...]) -> str:
    """The measured quantity the channels' units say (`QUANTITY_OF_UNITS`); acceleration otherwise
    (g, m/s^2, a logger's volts): the common OMA sensor."""
    found = {QUANTITY_OF_UNITS.get((u or "").lower().replace(" ", "")) for u in units}
    found.discard(None)
    return found.pop() if len(found) == 1 else "acceleration"


#: damping-ratio bounds of the fit (the single-series model's prior: `Oscillator.priors`)
ZETA_BOUNDS = (1e-4, 0.9)

_UNUSED_FACTS = DataFacts(1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0, np.zeros(0), np.zeros(0))


def modal_density(f_mode: float, zeta: float, freqs: np.ndarray, power: int) -> np.ndarray:
    """g / s: the Oscillator term's unit-rms PSD at `freqs` times (2 pi f)^(2 power)."""
    term = Oscillator("m")
    values = {"m.frequency": f_mode, "m.damping_ratio": zeta, "m.rms": 1.0}
    big_w = 2.0 * math.pi * freqs
    return term.psd(values, freqs, _UNUSED_FACTS) * big_w ** (2 * power)


def modal_log_slopes(f_mode: float, zeta: float, freqs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(d ln g / d ln f_mode, d ln g / d ln zeta) of `modal_density`: with w the mode's and W the
    ordinate's angular frequency, D = (w^2 - W^2)^2 + 4 zeta^2 w^2 W^2 and g ∝ zeta w^3 / D,
    d ln g / d ln w = 3 - [4 w^2 (w^2 - W^2) + 8 zeta^2 w^2 W^2] / D and d ln g / d ln zeta =
    1 - 8 zeta^2 w^2 W^2 / D."""
    w = 2.0 * math.pi * f_mode
    big_w = 2.0 * math.pi * freqs
    w2, big2 = w * w, big_w * big_w
    d = (w2 - big2) ** 2 + 4.0 * zeta * zeta * w2 * big2
    damp = 8.0 * zeta * zeta * w2 * big2 / d
    return 3.0 - (4.0 * w2 * (w2 - big2)) / d - damp, 1.0 - damp


@njit(cache=True, fastmath=False, nogil=True)
def band_terms(g, v, noise, bg, yr, yi, q, rvg, rdiag):  # pragma: no cover - compiled
    """One pass over the ordinates j: E_j = sum_m g[m, j] v_m v_m^T + diag(noise[j]) (+ bg[j] when
    bg has rows), its Cholesky factor, ln det E_j, the quadratic form Y_j^H E_j^{-1} Y_j (Y = yr + i
    yi) and, with R_j = E_j^{-1} - Re(u u^H), u = E_j^{-1} Y_j, the gradient's pieces: q[m, j] =
    v_m^T R_j v_m, rvg[m] = sum_j g[m, j] R_j v_m and rdiag[j] = diag R_j. Returns (sum ln det, sum
    quadratic form), or (nan, nan) where an E_j is not positive definite. Small C x C matrices in a
    compiled loop: ~10x faster than numpy's batched linear algebra and einsum at C = 3."""
    nm, nj = g.shape[0], g.shape[1]
    c = v.shape[1]
    e = np.empty((c, c))
    low = np.empty((c, c))
    inv = np.empty((c, c))
    r = np.empty((c, c))
    ur = np.empty(c)
    ui = np.empty(c)
    rv = np.empty(c)
    has_bg = bg.shape[0] > 0
    logdet, quad = 0.0, 0.0
    for m in range(nm):
        for a in range(c):
            rvg[m, a] = 0.0
    for j in range(nj):
        for a in range(c):
            for b in range(a + 1):
                acc = bg[j, a, b] if has_bg else 0.0
                for m in range(nm):
                    acc += g[m, j] * v[m, a] * v[m, b]
                if a == b:
                    acc += noise[j, a]
                e[a, b] = acc
        for a in range(c):
            for b in range(a + 1):
                acc = e[a, b]
                for k in range(b):
                    acc -= low[a, k] * low[b, k]
                if a == b:
                    if acc <= 0.0:
                        return np.nan, np.nan
                    low[a, a] = math.sqrt(acc)
                else:
                    low[a, b] = acc / low[b, b]
        for a in range(c):
            logdet += 2.0 * math.log(low[a, a])
        for col in range(c):  # L^-1, lower triangular
            for a in range(c):
                if a < col:
                    inv[a, col] = 0.0
                    continue
                acc = 1.0 if a == col else 0.0
                for k in range(col, a):
                    acc -= low[a, k] * inv[k, col]
                inv[a, col] = acc / low[a, a]
        for a in range(c):  # E^-1 = L^-T L^-1
            for b in range(a + 1):
                acc = 0.0
                for k in range(a, c):
                    acc += inv[k, a] * inv[k, b]
                r[a, b] = acc
                r[b, a] = acc
        for a in range(c):
            sr, si = 0.0, 0.0
            for b in range(c):
                sr += r[a, b] * yr[j, b]
                si += r[a, b] * yi[j, b]
            ur[a], ui[a] = sr, si
            quad += yr[j, a] * sr + yi[j, a] * si
        for a in range(c):
            for b in range(c):
                r[a, b] -= ur[a] * ur[b] + ui[a] * ui[b]
            rdiag[j, a] = r[a, a]
        for m in range(nm):
            qq = 0.0
            for a in range(c):
                acc = 0.0
                for b in range(c):
                    acc += r[a, b] * v[m, b]
                rv[a] = acc
                qq += v[m, a] * acc
                rvg[m, a] += g[m, j] * acc
            q[m, j] = qq
    return logdet, quad


@dataclass(frozen=True)
class BandLayout:
    """Where each parameter sits in x: M modes over C channels; `reference[m]` is the channel whose
    shape component is held at 1 for mode m."""

    modes: int
    channels: int
    reference: tuple[int, ...]

    @property
    def size(self) -> int:
        return 4 * self.modes + self.modes * (self.channels - 1) + 2 * self.channels

    def free(self, m: int) -> np.ndarray:
        """The channels whose shape components of mode m are free."""
        return np.array([c for c in range(self.channels) if c != self.reference[m]], dtype=int)

    def shape_slice(self, m: int) -> slice:
        o = 4 * self.modes + m * (self.channels - 1)
        return slice(o, o + self.channels - 1)

    @property
    def noise_slice(self) -> slice:
        """ln n_c, the channels' noise levels at the band's centre."""
        o = 4 * self.modes + self.modes * (self.channels - 1)
        return slice(o, o + self.channels)

    @property
    def tilt_slice(self) -> slice:
        """beta_c, the channels' noise slopes in log-log over the band."""
        o = self.noise_slice.stop
        return slice(o, o + self.channels)

    def tilt(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(x[self.tilt_slice], dtype=float)

    def alpha(self, x: np.ndarray) -> np.ndarray:
        """alpha_m, each modal force's log-log slope over the band."""
        return np.asarray(x[3 * self.modes : 4 * self.modes], dtype=float)

    def unpack(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(f (M,), zeta (M,), s (M,), raw shapes v (M, C) with the reference at 1, noise n (C,))."""
        m = self.modes
        f, zeta, s = np.exp(x[0:m]), np.exp(x[m : 2 * m]), np.exp(x[2 * m : 3 * m])
        v = np.ones((m, self.channels))
        for k in range(m):
            v[k, self.free(k)] = x[self.shape_slice(k)]
        return f, zeta, s, v, np.exp(x[self.noise_slice])

    def pack(self, f, zeta, s, v, n, tilt=None, alpha=None) -> np.ndarray:
        """x from (f, zeta, s, v, n, tilt, alpha (both default 0)); v is rescaled so that its
        reference component is 1 (s takes the square of the scale)."""
        x = np.empty(self.size)
        m = self.modes
        v = np.array(v, dtype=float).reshape(m, self.channels)
        s = np.array(s, dtype=float).reshape(m)
        for k in range(m):
            r = v[k, self.reference[k]]
            s[k] = s[k] * r * r
            v[k] = v[k] / r
            x[self.shape_slice(k)] = v[k, self.free(k)]
        x[0:m], x[m : 2 * m], x[2 * m : 3 * m] = np.log(f), np.log(zeta), np.log(s)
        x[3 * m : 4 * m] = 0.0 if alpha is None else alpha
        x[self.noise_slice] = np.log(n)
        x[self.tilt_slice] = 0.0 if tilt is None else tilt
        return x


class BandLikelihood:
    """ln L of the band's ordinates (module docstring) and its gradient in x."""

    def __init__(
        self, freqs: np.ndarray, y: np.ndarray, layout: BandLayout, power: int, background: np.ndarray | None = None
    ):
        self.freqs = np.asarray(freqs, dtype=float)
        self.y = y
        self.layout = layout
        self.power = power
        #: (J, C, C) held fixed: the in-band tails of the modes fitted in other bands
        self.background = background
        self._background = (
            np.ascontiguousarray(background, dtype=float) if background is not None else np.empty((0, 0, 0))
        )
        self.const = -self.freqs.size * layout.channels * math.log(math.pi)
        #: ln(f / the band's geometric centre): the noise's log-log slope is about the centre
        self.log_f = np.log(self.freqs / math.sqrt(self.freqs[0] * self.freqs[-1])) if self.freqs.size else self.freqs

    def densities(self, f: np.ndarray, zeta: np.ndarray, s: np.ndarray, alpha: np.ndarray) -> np.ndarray:
        """(M, J): each mode's g_m at the ordinates, s_m (f_j / f_m)^alpha_m times `modal_density`."""
        return np.array(
            [
                s[k] * (self.freqs / f[k]) ** alpha[k] * modal_density(f[k], zeta[k], self.freqs, self.power)
                for k in range(f.size)
            ]
        ).reshape(f.size, self.freqs.size)

    @property
    def y(self) -> np.ndarray:
        return self._y

    @y.setter
    def y(self, value: np.ndarray) -> None:
        self._y = np.asarray(value, dtype=complex)
        self._yr = np.ascontiguousarray(self._y.real)
        self._yi = np.ascontiguousarray(self._y.imag)

    def noise(self, x: np.ndarray) -> np.ndarray:
        """(J, C): each channel's noise n_c (f_j / f_centre)^beta_c."""
        n = np.exp(x[self.layout.noise_slice])
        return n[None, :] * np.exp(self.log_f[:, None] * self.layout.tilt(x)[None, :])

    def covariance(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(E_j (J, C, C), g (M, J))."""
        f, zeta, s, v, n = self.layout.unpack(x)
        g = self.densities(f, zeta, s, self.layout.alpha(x))
        c = v.shape[1]
        e = np.zeros((self.freqs.size, c, c))
        for k in range(f.size):  # a few modes: broadcast products beat einsum's general loop 5x
            e += g[k][:, None, None] * np.outer(v[k], v[k])[None, :, :]
        e[:, np.arange(n.size), np.arange(n.size)] += self.noise(x)
        if self.background is not None:
            e += self.background
        return e, g

    def fisher_diagonal(self, x: np.ndarray) -> np.ndarray:
        """The diagonal of Whittle's expected Fisher information in x, F_aa = sum_j tr((E_j^{-1}
        dE_j/dx_a)^2): each parameter's scale for the optimizer (one evaluation's inverse)."""
        lay = self.layout
        f, zeta, _, v, _ = lay.unpack(x)
        alpha = lay.alpha(x)
        e, g = self.covariance(x)
        try:
            einv = np.linalg.inv(e)
        except np.linalg.LinAlgError:  # an E_j singular to working precision: no scale information
            return np.ones(lay.size)
        out = np.empty(lay.size)
        m = lay.modes
        diag = np.einsum("jcc->jc", einv)
        for k in range(m):
            ev = einv @ v[k]  # (J, C)
            q = ev @ v[k]  # v^T E^-1 v
            dlf, dlz = modal_log_slopes(f[k], zeta[k], self.freqs)
            dlf = dlf - alpha[k]
            gq2 = (g[k] * q) ** 2
            out[k], out[m + k], out[2 * m + k] = np.sum(gq2 * dlf**2), np.sum(gq2 * dlz**2), np.sum(gq2)
            out[3 * m + k] = np.sum(gq2 * np.log(self.freqs / f[k]) ** 2)
            shape = 2.0 * (g[k, :, None] ** 2) * (diag * q[:, None] + ev**2)
            out[lay.shape_slice(k)] = shape.sum(axis=0)[lay.free(k)]
        noise2 = (diag * self.noise(x)) ** 2
        out[lay.noise_slice] = noise2.sum(axis=0)
        out[lay.tilt_slice] = (noise2 * self.log_f[:, None] ** 2).sum(axis=0)
        return out

    def log_likelihood(self, x: np.ndarray) -> float:
        value, _ = self.value_and_gradient(x, gradient=False)
        return value

    def value_and_gradient(self, x: np.ndarray, gradient: bool = True) -> tuple[float, np.ndarray | None]:
        """(ln L, d ln L / dx); -inf (and None) where E is not positive definite."""
        lay = self.layout
        f, zeta, s, v, _ = lay.unpack(x)
        alpha = lay.alpha(x)
        g = self.densities(f, zeta, s, alpha)
        noise = self.noise(x)
        m, nj = lay.modes, self.freqs.size
        q, rvg, rdiag = np.empty((m, nj)), np.empty((m, lay.channels)), np.empty((nj, lay.channels))
        bg = self._background
        c_ = np.ascontiguousarray  # one compiled specialization: every array C-contiguous float64
        logdet, quad = band_terms(c_(g), c_(v), c_(noise), bg, self._yr, self._yi, q, rvg, rdiag)
        value = self.const - logdet - quad
        if not math.isfinite(value):
            return -math.inf, None
        if not gradient:
            return float(value), None
        grad = np.empty(lay.size)
        for k in range(m):
            dlf, dlz = modal_log_slopes(f[k], zeta[k], self.freqs)
            qg = q[k] * g[k]
            grad[k] = -np.sum(qg * (dlf - alpha[k]))
            grad[m + k] = -np.sum(qg * dlz)
            grad[2 * m + k] = -np.sum(qg)
            grad[3 * m + k] = -np.sum(qg * np.log(self.freqs / f[k]))
            grad[lay.shape_slice(k)] = -2.0 * rvg[k][lay.free(k)]
        rn = rdiag * noise
        grad[lay.noise_slice] = -rn.sum(axis=0)
        grad[lay.tilt_slice] = -(rn * self.log_f[:, None]).sum(axis=0)
        return float(value), grad

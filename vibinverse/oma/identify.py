"""Operational modal analysis of a multi-channel record: bands picked from the singular values of the
spectral density matrix, each band's modes fitted by the multi-channel frequency-domain likelihood
(`vibinverse.oma.band_model`), the mode count per band chosen by BIC, and the posterior of f, zeta
and the unit shapes from the Laplace approximation at the MAP (draws mapped through the shape's
normalization, so that the intervals of the unit-shape components are not linearized).

Stages:

1. Peaks of the first singular value (`singular_values`) more prominent than `PROMINENCE` (natural
   log) above their surroundings and above `MIN_CYCLES` cycles per record; the strongest
   `MAX_BANDS` kept (or the `modes` strongest when the count is given).
2. Each peak's band: its frequency +- `BAND_WIDTHS` half-power half-widths (from the singular
   value's width at first, then from the fitted damping), at least `MIN_ORDINATES` ordinates;
   overlapping bands merge and fit their peaks together.
3. Per band, fits with 0 .. peaks + 1 modes (at most `MAX_MODES_PER_BAND`), the added mode started
   where the second singular value peaks; BIC picks the count (unless `modes` fixed it).
4. Laplace: the Hessian of the log posterior in the optimizer's coordinates (central differences of
   the closed-form gradient), `DRAWS` draws, 5 % and 95 % quantiles.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

import numpy as np
from scipy import optimize
from threadpoolctl import threadpool_limits

from vibinverse.detection import BROAD_DAMPING
from vibinverse.errors import InputError, NumericalError
from vibinverse.io.channels import Channels
from vibinverse.oma.band_model import (
    QUANTITY_POWER,
    ZETA_BOUNDS,
    BandLayout,
    BandLikelihood,
    modal_density,
    quantity_of,
)
from vibinverse.oma.input_output import identify_io
from vibinverse.oma.peaks import (
    MAX_BAND_ZETA,
    MAX_BANDS,
    MAX_MODES_PER_BAND,
    MIN_ORDINATES,
    START_ZETA,
    Peak,
    group_bands,
    pick_peaks,
)
from vibinverse.oma.result import BandFit, OmaMode, OmaResult, mode_from_draws, signed_unit
from vibinverse.oma.spectral_matrix import Ordinates, SingularValues, ordinates, singular_values

log = logging.getLogger(__name__)

BROAD_START = 3.0  # every fit is also started from this many times its damping ratios
DRAWS = 4000
MAX_TILT = 8.0  # bound of a channel noise's log-log slope across a band
#: below this curvature (sd 5 in ln) a channel's noise level is unidentified in the band (`_modes_of`)
FLAT_CURVATURE = 1.0 / 25.0
#: a fitted "mode" more damped than this is the spectrum's shape (coloured excitation, a filter's
#: roll-off, a neighbour's tail), not a structural mode: an order holding one is not chosen
MAX_MODE_ZETA = 0.1
PASSES = 1  # fits of every band before the order search, whose modes are the other bands' background
#: a mode whose decay time 1 / (2 pi zeta f) is longer than this fraction of the record gets a warning:
#: the ordinates are then not independent (Whittle's approximation) and intervals may be too narrow
DECAY_FRACTION = 0.05


@dataclass
class _Fitted:
    """A mode's current fit: its contribution s g(f; f, zeta) v v^T to every band's spectral matrix."""

    f: float
    zeta: float
    s: float
    v: np.ndarray
    alpha: float = 0.0
    band: tuple[float, float] = (0.0, math.inf)  # where it was fitted: its force's power law holds there

    def density(self, freqs: np.ndarray, power: int) -> np.ndarray:
        """Its spectral density at `freqs`; outside its band the force is held at the band edge's level
        (the power law fitted across +-30 % is no model of the force far away)."""
        held = np.clip(freqs, *self.band)
        return self.s * (held / self.f) ** self.alpha * modal_density(self.f, self.zeta, freqs, power)

    @property
    def height(self) -> float:
        """Its strength: the modal response's variance over the channels (the unit-rms density's
        integral is 1), not its peak (a spike's peak is high and its variance small)."""
        return float(self.s * self.v @ self.v)


class _BandFitter:
    """Fits of one band at several mode counts (stage 3) and the Laplace draws (stage 4)."""

    def __init__(self, ords: Ordinates, lo: float, hi: float, power: int, others: list[_Fitted]):
        self.freqs, self.y = ords.band(lo, hi)
        self.lo, self.hi, self.power = lo, hi, power
        self.channels = ords.y.shape[1]
        self.background = None
        if others:
            g = np.array([o.density(self.freqs, power) for o in others])
            v = np.array([o.v for o in others])
            self.background = np.einsum("mj,mc,md->jcd", g, v, v)
        self.noise0 = np.maximum(self._edge_noise(), 1e-300)

    def _edge_noise(self) -> np.ndarray:
        """Each channel's |Y|^2 in the band's outer fifth on both sides (a start for n)."""
        j = self.freqs.size
        k = max(2, j // 10)
        edge = np.r_[self.y[:k], self.y[-k:]]
        level = np.median(np.abs(edge) ** 2, axis=0) / math.log(2.0)  # median of an exponential -> its mean
        level = np.maximum(level, 1e-10 * max(float(level.max()), 1e-300))  # a silent channel: a tiny floor
        if self.background is not None:
            tails = np.einsum("jcc->jc", np.r_[self.background[:k], self.background[-k:]])
            level = np.maximum(level - np.median(tails, axis=0), 0.05 * level)
        return level

    def _start_shape(self, f: float, width: float) -> np.ndarray:
        near = np.abs(self.freqs - f) <= max(width, 2.5 * (self.freqs[1] - self.freqs[0]))
        yy = self.y[near] if near.sum() >= 2 else self.y
        s = (yy.T @ yy.conj()).real
        _w, u = np.linalg.eigh(s)
        return u[:, -1]

    def _refined(self, f: float, zeta: float) -> float:
        """The frequency within +-3 half-power half-widths of f where the trace of the spectral matrix,
        averaged over one half-power width, peaks (the singular value's peak can sit a Welch bin or
        a noise bump away)."""
        if self.freqs.size < 3:
            return f
        df = self.freqs[1] - self.freqs[0]
        k = min(max(1, round(zeta * f / df)), (self.freqs.size - 1) // 2)
        trace = np.convolve((np.abs(self.y) ** 2).sum(axis=1), np.ones(2 * k + 1) / (2 * k + 1), "same")
        near = np.abs(self.freqs - f) <= 3.0 * zeta * f + df
        if not near.any():
            return f
        return float(self.freqs[near][int(np.argmax(trace[near]))])

    def start(self, peaks: list[tuple[float, float]]) -> tuple[BandLayout, np.ndarray]:
        """x at peak frequencies and damping ratios `peaks`, shapes from the principal eigenvector
        near each, levels from the peak height above the noise."""
        m = len(peaks)
        if m == 1:  # a lone mode: its start at the in-band trace's smoothed peak near the given one
            peaks = [(self._refined(*peaks[0]), peaks[0][1])]
        shapes = np.array([self._start_shape(f, z * f) for f, z in peaks]).reshape(m, self.channels)
        ref = tuple(int(np.argmax(np.abs(v))) for v in shapes)
        lay = BandLayout(m, self.channels, ref)
        s = []
        for (f, z), v in zip(peaks, shapes, strict=True):
            j = int(np.argmin(np.abs(self.freqs - f)))
            lo, hi = max(0, j - 2), min(self.freqs.size, j + 3)
            top = float(np.mean(np.abs(self.y[lo:hi] @ v) ** 2))
            unit = modal_density(f, z, np.array([f]), self.power)[0]
            s.append(max(top - float(self.noise0 @ v**2), 0.1 * top) / unit)
        if m == 0:
            return lay, np.r_[np.log(self.noise0), np.zeros(self.channels)]
        x = lay.pack(np.array([p[0] for p in peaks]), np.array([p[1] for p in peaks]), np.array(s), shapes, self.noise0)
        return lay, x

    def bounds(self, lay: BandLayout, x: np.ndarray) -> list[tuple[float | None, float | None]]:
        m = lay.modes
        b: list[tuple[float | None, float | None]] = [(None, None)] * lay.size
        for k in range(m):
            b[k] = (math.log(self.lo), math.log(self.hi))
            b[m + k] = (math.log(ZETA_BOUNDS[0]), math.log(ZETA_BOUNDS[1]))
            b[2 * m + k] = (x[2 * m + k] - 40.0, x[2 * m + k] + 40.0)
            b[3 * m + k] = (-MAX_TILT, MAX_TILT)
        ns = lay.noise_slice
        for c in range(ns.start, ns.stop):
            b[c] = (x[c] - 40.0, x[c] + 40.0)
        for c in range(lay.tilt_slice.start, lay.tilt_slice.stop):
            b[c] = (-MAX_TILT, MAX_TILT)
        return b

    @staticmethod
    def log_posterior(lik: BandLikelihood, x: np.ndarray) -> tuple[float, np.ndarray | None]:
        """ln L + ln prior (frequency uniform in the band: + ln f in the optimizer's ln f; log-uniform
        damping, levels and noise: flat; shape components flat)."""
        v, g = lik.value_and_gradient(x)
        m = lik.layout.modes
        if g is None:
            return v, None
        g = g.copy()
        g[:m] += 1.0
        return v + float(np.sum(x[:m])), g

    def fit(self, peaks: list[tuple[float, float]], broad: bool = False) -> tuple[BandLikelihood, np.ndarray, float]:
        """(likelihood, MAP x, ln L at it) from `peaks`; with `broad` the better of that and the fit
        from the same frequencies with BROAD_START times the damping (a lightly damped mode's
        likelihood has local optima on periodogram spikes; from a broad start the fit narrows onto
        the mode): for starts read off the spectrum, not for fitted ones."""
        fits = [self._fit_from(peaks)]
        if peaks and broad:
            fits.append(self._fit_from([(f, min(BROAD_START * max(z, START_ZETA), MAX_BAND_ZETA)) for f, z in peaks]))
        return max(fits, key=lambda t: t[2] if math.isfinite(t[2]) else -math.inf)

    def _fit_from(self, peaks: list[tuple[float, float]]) -> tuple[BandLikelihood, np.ndarray, float]:
        lay, x0 = self.start(peaks)
        lik = BandLikelihood(self.freqs, self.y, lay, self.power, self.background)
        x = self._maximize(lik, x0, 2000)
        # re-gauge on the MAP's largest shape component (the reported sign convention), refit briefly
        f, zeta, s, v, n = lay.unpack(x)
        ref = tuple(int(np.argmax(np.abs(vk))) for vk in v)
        if ref != lay.reference:
            tilt, alpha = lay.tilt(x), lay.alpha(x)
            lay = BandLayout(lay.modes, lay.channels, ref)
            lik = BandLikelihood(self.freqs, self.y, lay, self.power, self.background)
            x = self._maximize(lik, lay.pack(f, zeta, s, v, n, tilt, alpha), 500)
        return lik, x, lik.log_likelihood(x)

    def _maximize(self, lik: BandLikelihood, x0: np.ndarray, maxiter: int) -> np.ndarray:
        """The MAP from x0: L-BFGS-B in coordinates scaled by the expected Fisher information's
        diagonal at x0 (ln f is ~1e3 times better determined than a noise level: unscaled, the
        optimizer takes hundreds of steps)."""
        fisher = lik.fisher_diagonal(x0) if math.isfinite(lik.log_likelihood(x0)) else np.ones(x0.size)
        scale = 1.0 / np.sqrt(np.clip(fisher, 1e-2, None))

        def neg(z: np.ndarray) -> tuple[float, np.ndarray]:
            v, g = self.log_posterior(lik, x0 + z * scale)
            if g is None or not math.isfinite(v):
                return 1e300, np.zeros_like(z)
            return -v, -g * scale

        bounds = [
            (None if lo is None else (lo - a) / sc, None if hi is None else (hi - a) / sc)
            for (lo, hi), a, sc in zip(self.bounds(lik.layout, x0), x0, scale, strict=True)
        ]
        res = optimize.minimize(
            neg, np.zeros(x0.size), jac=True, method="L-BFGS-B", bounds=bounds, options={"maxiter": maxiter}
        )
        return x0 + res.x * scale

    def hessian(self, lik: BandLikelihood, x: np.ndarray) -> np.ndarray:
        """- d^2 ln posterior / dx^2 by central differences of the closed-form gradient."""
        k = x.size
        h = np.empty((k, k))
        for i in range(k):
            step = 1e-4 * max(1.0, abs(x[i])) if i >= 3 * lik.layout.modes else 1e-5  # ln f, ln zeta, ln s: 1e-5
            e = np.zeros(k)
            e[i] = step
            _, gp = self.log_posterior(lik, x + e)
            _, gm = self.log_posterior(lik, x - e)
            if gp is None or gm is None:
                raise NumericalError(f"band {self.lo:.4g}-{self.hi:.4g} Hz: the posterior is undefined beside its MAP")
            h[:, i] = -(gp - gm) / (2.0 * step)
        return 0.5 * (h + h.T)


def _positive_definite(h: np.ndarray) -> bool:
    return bool(np.all(np.isfinite(h))) and bool(np.all(np.linalg.eigvalsh(h) > 0))


def _modes_of(fitter: _BandFitter, lik: BandLikelihood, x: np.ndarray, rng: np.random.Generator) -> list[OmaMode]:
    """The band's modes with Laplace intervals (stage 4)."""
    lay = lik.layout
    f, zeta, s, v, _ = lay.unpack(x)
    warn: list[str] = []
    try:
        hess = fitter.hessian(lik, x)
        # a noise level the band cannot see (the mode outshines it at every ordinate) has a flat
        # log posterior towards 0: held at its MAP (weakly coupled to the rest) instead of inverted
        modal = np.arange(x.size) < lik.layout.noise_slice.start
        keep = (np.diag(hess) > FLAT_CURVATURE) | modal
        ok = _positive_definite(hess[np.ix_(keep, keep)])
        if not ok:  # a noise level on a ridge of the likelihood: the modal parameters given the noise levels
            keep = modal
            ok = _positive_definite(hess[np.ix_(keep, keep)])
            if ok:
                warn.append("channel noise levels poorly determined: intervals conditional on their MAP values")
        cov = np.linalg.inv(hess[np.ix_(keep, keep)]) if ok else None
    except (np.linalg.LinAlgError, NumericalError):
        ok = False
    if ok:
        draws = np.repeat(x[None, :], DRAWS, axis=0)
        draws[:, keep] = rng.multivariate_normal(x[keep], cov, size=DRAWS, method="cholesky")
    else:
        warn.append("the posterior is not locally Gaussian at the MAP (Hessian not positive definite): no interval")
        draws = x[None, :]
    modes = []
    for k in range(lay.modes):
        fd = np.exp(draws[:, k])
        zd = np.exp(draws[:, lay.modes + k])
        vd = np.ones((draws.shape[0], lay.channels))
        vd[:, lay.free(k)] = draws[:, lay.shape_slice(k)]
        ud = vd / np.linalg.norm(vd, axis=1, keepdims=True)  # reference component held positive
        shape = signed_unit(v[k])
        sign = 1.0 if shape[lay.reference[k]] >= 0 else -1.0
        ud *= sign
        peak = s[k] * modal_density(f[k], zeta[k], np.array([f[k]]), lik.power)[0] * float(v[k] @ v[k])
        mode_warn = list(warn)
        modes.append(
            mode_from_draws(f[k], zeta[k], shape, (fd, zd, ud), (fitter.lo, fitter.hi), 2.0 * peak, mode_warn, ok)
        )
    return modes


def _second_peak(fitter: _BandFitter, taken: list[float]) -> float:
    """Where an added mode starts: the in-band ordinate farthest (in the principal-component
    residual) from the modes already there, i.e. the peak of the spectral matrix's second eigenvalue."""
    yy = fitter.y
    outer = np.einsum("jc,jd->jcd", yy, yy.conj()).real
    kernel = np.ones(5)
    smooth = np.apply_along_axis(lambda col: np.convolve(col, kernel, "same"), 0, outer.reshape(yy.shape[0], -1))
    w = np.linalg.eigvalsh(smooth.reshape(outer.shape))
    lam2 = w[:, -2] if w.shape[1] > 1 else w[:, -1]
    order = np.argsort(lam2)[::-1]
    for j in order:
        if all(abs(fitter.freqs[j] - t) > 2 * (fitter.freqs[1] - fitter.freqs[0]) for t in taken):
            return float(fitter.freqs[j])
    return float(fitter.freqs[order[0]])


def _worst_fitted(fitter: _BandFitter, lik: BandLikelihood, x: np.ndarray, taken: list[float]) -> float:
    """Where the fit falls shortest: the peak of sum_c |Y_jc|^2 / E_jcc (smoothed over 5 ordinates)
    away from the modes already there (two modes of one shape, which the second eigenvalue misses)."""
    e, _ = lik.covariance(x)
    ratio = (np.abs(fitter.y) ** 2 / np.einsum("jcc->jc", e)).sum(axis=1)
    smooth = np.convolve(ratio, np.ones(5) / 5.0, "same") if ratio.size >= 5 else ratio
    df = fitter.freqs[1] - fitter.freqs[0] if fitter.freqs.size > 1 else 0.0
    for j in np.argsort(smooth)[::-1]:
        if all(abs(fitter.freqs[j] - t) > 2 * df for t in taken):
            return float(fitter.freqs[j])
    return float(fitter.freqs[int(np.argmax(smooth))])


def _order_fits(
    fitter: _BandFitter, starts: list[tuple[float, float]], counts: list[int]
) -> dict[int, tuple[BandLikelihood, np.ndarray, float]]:
    """The band's MAP fit at each mode count in `counts`: upwards from the strongest starts (the
    count past the peaks adds a mode where the second eigenvalue peaks), then downwards, each count
    also started from the next one's fit less its weakest mode; the better of the two kept (a
    lightly damped mode's likelihood has local optima in f between the ordinates)."""
    out: dict[int, tuple[BandLikelihood, np.ndarray, float]] = {}
    for m in counts:
        if m <= len(starts):
            fits = [fitter.fit(starts[:m])]
        else:  # an added mode: where the second eigenvalue peaks, and where the last fit falls shortest
            zeta = float(np.median([p[1] for p in starts]))
            where = {_second_peak(fitter, [p[0] for p in starts])}
            if m - 1 in out:
                where.add(_worst_fitted(fitter, *out[m - 1][:2], [p[0] for p in starts]))
            fits = [fitter.fit([*starts, (f, zeta)]) for f in sorted(where)]
        fit = max(fits, key=lambda t: t[2] if math.isfinite(t[2]) else -math.inf)
        if math.isfinite(fit[2]):
            out[m] = fit
    for m in sorted(out, reverse=True):
        if m - 1 not in out or m - 1 < 1:
            continue
        kept = sorted(_fitted(out[m][0], out[m][1]), key=lambda o: -o.height)[: m - 1]
        fit = fitter.fit([(o.f, o.zeta) for o in kept])
        if math.isfinite(fit[2]) and fit[2] > out[m - 1][2]:
            out[m - 1] = fit
    return out


def _starts(group: list[Peak]) -> list[tuple[float, float]]:
    """(f, zeta) starts of a band's modes, the strongest first."""
    return [(p.f, p.zeta) for p in sorted(group, key=lambda p: -p.prominence)]


def _fitted(lik: BandLikelihood, x: np.ndarray) -> list[_Fitted]:
    f, zeta, s, v, _ = lik.layout.unpack(x)
    alpha = lik.layout.alpha(x)
    band = (float(lik.freqs[0]), float(lik.freqs[-1]))
    return [
        _Fitted(float(f[k]), float(zeta[k]), float(s[k]), v[k].copy(), float(alpha[k]), band) for k in range(f.size)
    ]


@threadpool_limits.wrap(limits=1, user_api="blas")  # C x C matrices: BLAS threads only contend
def identify(
    channels: Channels,
    *,
    modes: int | None = None,
    quantity: str | None = None,
    band: tuple[float, float] | None = None,
    seed: int = 0,
) -> OmaResult:
    """Modes, damping ratios and unit shapes with 90 % intervals from a multi-channel record (module
    docstring). `modes`: the number of modes (default: chosen per band by BIC); `quantity`:
    displacement, velocity or acceleration (default: from the channels' units, else acceleration);
    `band`: (lo, hi) Hz to search (default: all). A channel flagged as a measured input makes it an
    input-output identification (`vibinverse.oma.input_output.identify_io`)."""
    if channels.inputs:  # a measured excitation: the responses fitted given it
        return identify_io(channels, modes=modes, quantity=quantity, band=band, seed=seed)
    t0 = time.perf_counter()
    if quantity is None:
        quantity = quantity_of(channels.units)
    if quantity not in QUANTITY_POWER:
        raise InputError(f"quantity: {quantity!r} is not one of {', '.join(QUANTITY_POWER)}")
    if modes is not None and not 1 <= modes <= MAX_BANDS * MAX_MODES_PER_BAND:
        raise InputError(f"modes: must be in [1, {MAX_BANDS * MAX_MODES_PER_BAND}], got {modes}")
    power = QUANTITY_POWER[quantity]
    ords = ordinates(channels)
    span = ords.n * ords.dt
    nyq = 0.5 / ords.dt
    if band is not None and nyq < band[1] <= nyq * (1 + 1e-6):  # Nyquist as the stamps round it
        band = (band[0], nyq)
    if band is not None and not (0 <= band[0] < band[1] <= nyq):
        raise InputError(f"band: need 0 <= lo < hi <= Nyquist {nyq:g} Hz, got {band[0]:g}-{band[1]:g}")
    sv = singular_values(channels)
    if band is not None:
        keep = (sv.freqs >= band[0]) & (sv.freqs <= band[1])
        sv_band = SingularValues(sv.freqs[keep], sv.values[keep], sv.vectors[keep], sv.segments)
    else:
        sv_band = sv
    if sv_band.freqs.size < 5:
        raise InputError("band: holds fewer than 5 frequencies of the spectral matrix; widen it")
    peaks = pick_peaks(sv_band, span, modes)
    notes = list(ords.notes)
    rng = np.random.default_rng(seed)
    # passes: every band fitted with the other bands' current modes as its fixed background
    current: list[_Fitted] = []
    estimates = peaks
    for _ in range(PASSES):
        fitted: list[_Fitted] = []
        kept: list[Peak] = []  # peaks whose fit went broad: tried again in the order search
        for lo, hi, group in group_bands(estimates, ords.resolution, nyq):
            others = [o for o in current if not lo <= o.f <= hi]
            fitter = _BandFitter(ords, lo, hi, power, others)
            if fitter.freqs.size < MIN_ORDINATES // 2:
                continue
            lik, x, _ = fitter.fit(_starts(group), broad=True)
            narrow = [o for o in _fitted(lik, x) if o.zeta <= MAX_MODE_ZETA]  # a broad bump is no mode
            fitted += narrow
            kept += [p for p in group if all(abs(o.f - p.f) > 3 * p.zeta * p.f for o in narrow)]
        current = fitted
        estimates = [Peak(o.f, o.zeta, o.height) for o in current] + kept
    found: list[OmaMode] = []
    fits: list[BandFit] = []
    for lo, hi, group in group_bands(estimates, ords.resolution, nyq):
        others = [o for o in current if not lo <= o.f <= hi]
        fitter = _BandFitter(ords, lo, hi, power, others)
        if fitter.freqs.size < MIN_ORDINATES // 2:
            continue
        starts = _starts(group)
        counts = [len(starts)] if modes is not None else list(range(min(len(starts) + 1, MAX_MODES_PER_BAND) + 1))
        tried = _order_fits(fitter, starts, counts)
        nobs = 2 * fitter.freqs.size * fitter.channels
        orders: dict[int, dict] = {}
        best: tuple[float, BandLikelihood, np.ndarray] | None = None
        for m, (lik_m, x_m, ll_m) in sorted(tried.items()):
            bic = -2.0 * ll_m + lik_m.layout.size * math.log(nobs)
            fm, zm, *_ = lik_m.layout.unpack(x_m)
            # a "mode" past MAX_MODE_ZETA stands in for the spectrum's shape; one whose half-power
            # width 2 zeta f is below the ordinates' spacing is a spike (or a line), not a resolved mode
            broad = bool(np.any(zm > MAX_MODE_ZETA)) or bool(np.any(2.0 * zm * fm < ords.resolution))
            orders[m] = {
                "bic": bic,
                "log_likelihood": ll_m,
                "frequencies": fm.tolist(),
                "damping_ratios": zm.tolist(),
                "eligible": not broad,
            }
            if broad:
                continue
            if best is None or bic < best[0]:
                best = (bic, lik_m, x_m)
        if best is None:
            continue
        chosen = best[1].layout.modes
        fits.append(BandFit(fitter.lo, fitter.hi, int(fitter.freqs.size), orders, chosen))
        if chosen:
            found += _modes_of(fitter, best[1], best[2], rng)
    found.sort(key=lambda m: m.frequency)
    for m in found:
        if not m.claimed:
            m.warnings.append(
                f"damping ratio {m.damping_ratio:.3g} > {BROAD_DAMPING:g}: a broad hump, not claimed as a resonance"
            )
        tau = 1.0 / (2.0 * math.pi * m.damping_ratio * m.frequency)
        if tau > DECAY_FRACTION * span:
            m.warnings.append(
                f"decay time {tau:.3g} s is {tau / span:.1%} of the {span:.4g} s record: the band likelihood needs "
                f"records much longer than it; the interval may be too narrow"
            )
    if not found:
        notes.append("no mode found: no band's evidence favoured a mode over channel noise")
    return OmaResult(
        modes=found,
        names=ords.names,
        units=ords.units,
        quantity=quantity,
        bands=fits,
        sv_freqs=sv.freqs,
        sv_values=sv.values,
        samples=ords.n,
        fs=1.0 / ords.dt,
        seconds=time.perf_counter() - t0,
        search=(float(band[0]), float(band[1])) if band is not None else (0.0, nyq),
        notes=notes,
    )

"""Input-output modal identification: a measured force (a hammer, a shaker, a swept drive) is the
known excitation, and the responses' Fourier ordinates are fitted given it (as pyOMA2's OMAX and
classical experimental modal analysis do).

In a band, with F_j the input's ordinate and Y_j the C responses' (`vibinverse.oma.spectral_matrix`),

    Y_j = [ sum_m a_m h_m(f_j) + r0 + r2 / W_j^2 ] F_j + e_j,   e_j ~ CN(0, diag(n_1 .. n_C)),

h_m(f) = (i W)^p / (w_m^2 - W^2 + 2 i zeta_m w_m W) the mode's receptance times (i W)^p for a
velocity (p = 1) or acceleration (p = 2) response (W = 2 pi f, w_m = 2 pi f_m), a_m the real vector
of the mode's residues over the channels (its shape times its participation at the input: real for
classically damped modes), r0 and r2 real residual terms of the modes above and below the band.
Given (f_m, zeta_m) the rest enters linearly and the noise is diagonal, so each channel's residues
and noise are least squares (variable projection): the profile log-likelihood

    ln L_p(f, zeta) = - sum_c J (ln(pi n_c) + 1),  n_c = RSS_c / J,

is maximized over the 2M nonlinear parameters only; its Hessian gives their Laplace covariance, and
the residues' conditional least-squares covariance their intervals given them (draws of f, zeta,
then of a given those). The shape is a_m / |a_m| (largest component positive).
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np
from scipy import optimize, signal

from vibinverse.errors import DataError, InputError
from vibinverse.io.channels import Channels
from vibinverse.oma.band_model import QUANTITY_POWER, ZETA_BOUNDS, quantity_of
from vibinverse.oma.peaks import MAX_BANDS, MAX_MODES_PER_BAND, Peak, group_bands, pick_peaks
from vibinverse.oma.result import BandFit, OmaMode, OmaResult, mode_from_draws, signed_unit
from vibinverse.oma.spectral_matrix import SingularValues, detrended, step_of

log = logging.getLogger(__name__)

DRAWS = 2000
MIN_COHERENCE = 0.5
#: an FRF with a coherent input is smooth: a peak half the height of a response spectrum's counts
FRF_PROMINENCE = 0.5  # a band's ordinates where the input drives the responses (median coherence)


def receptance(f_mode: float, zeta: float, freqs: np.ndarray, power: int) -> np.ndarray:
    """h(f) = (i W)^p / (w^2 - W^2 + 2 i zeta w W) at `freqs` (module docstring)."""
    w = 2.0 * math.pi * f_mode
    big_w = 2.0 * math.pi * freqs
    return (1j * big_w) ** power / (w * w - big_w * big_w + 2j * zeta * w * big_w)


class IOBand:
    """The profile likelihood of one band (module docstring)."""

    def __init__(self, freqs: np.ndarray, y: np.ndarray, force: np.ndarray, power: int):
        self.freqs, self.y, self.force, self.power = freqs, y, force, power
        self.residual = np.column_stack([force, force / (2.0 * math.pi * freqs) ** 2])
        self.yr = np.vstack([y.real, y.imag])  # the responses' real and imaginary parts, stacked

    def design(self, f: np.ndarray, zeta: np.ndarray) -> np.ndarray:
        """(J, 3M + 2) complex columns: h_m F (the forced response), F, F / W^2 (residuals), and per
        mode h_m and i W h_m without F: the transient term of a finite record (the modal states'
        difference between its start and end, Pintelon & Schoukens), whose truncated ringing would
        otherwise read as extra damping."""
        hs = [receptance(a, b, self.freqs, self.power) for a, b in zip(f, zeta, strict=True)]
        big_w = 2.0 * math.pi * self.freqs
        forced = [h * self.force for h in hs]
        transient = [c for h in hs for c in (h, 1j * big_w * h)]
        return np.column_stack([*forced, self.residual, *transient]) if hs else self.residual

    def solve(self, f: np.ndarray, zeta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(coefficients (M + 2, C) real, noise n (C,), the real design's (X^T X)^-1)."""
        x = self.design(f, zeta)
        xr = np.vstack([x.real, x.imag])  # real coefficients of complex columns: stacked real system
        yr = self.yr
        scale = np.linalg.norm(xr, axis=0)
        scale[scale == 0] = 1.0
        coef, *_ = np.linalg.lstsq(xr / scale, yr, rcond=None)
        coef = coef / scale[:, None]
        resid = yr - xr @ coef
        n = np.maximum((resid**2).sum(axis=0) / self.freqs.size, 1e-300)  # E|e|^2 = n: two halves of n/2
        xtx = (xr / scale).T @ (xr / scale)
        cov = np.linalg.pinv(xtx) / np.outer(scale, scale)
        return coef, n, cov

    def noise(self, f: np.ndarray, zeta: np.ndarray) -> np.ndarray:
        """Each channel's noise n at the least-squares coefficients (as `solve`, by a QR
        factorization: the profile's inner call)."""
        x = self.design(f, zeta)
        xr = np.vstack([x.real, x.imag])
        scale = np.linalg.norm(xr, axis=0)
        scale[scale == 0] = 1.0
        q, _ = np.linalg.qr(xr / scale)
        resid = self.yr - q @ (q.T @ self.yr)
        return np.maximum((resid**2).sum(axis=0) / self.freqs.size, 1e-300)

    def shortfall(self, f: np.ndarray, zeta: np.ndarray) -> float:
        """Where the fit with modes (f, zeta) falls shortest: the peak of sum_c |residual_jc|^2 / n_c
        (smoothed over 5 ordinates) at least 2 ordinates from those modes: a start for one more."""
        x = self.design(f, zeta)
        coef, n, _ = self.solve(f, zeta)
        resid = self.y - x @ coef
        ratio = (np.abs(resid) ** 2 / n).sum(axis=1)
        smooth = np.convolve(ratio, np.ones(5) / 5.0, "same") if ratio.size >= 5 else ratio
        df = self.freqs[1] - self.freqs[0] if self.freqs.size > 1 else 0.0
        for j in np.argsort(smooth)[::-1]:
            if np.all(np.abs(self.freqs[j] - f) > 2 * df):
                return float(self.freqs[j])
        return float(self.freqs[int(np.argmax(smooth))])

    def orders(self, starts: list[tuple[float, float]], counts: list[int]) -> dict[int, tuple[np.ndarray, float]]:
        """The fit at each mode count: from the `count` strongest starts, and from the fit one count
        lower plus the next start (past the starts: where that fit falls shortest, `shortfall`),
        the better of the two kept."""
        out: dict[int, tuple[np.ndarray, float]] = {}
        zeta0 = float(np.median([z for _, z in starts])) if starts else 0.01
        for m in counts:
            tries = [starts[:m]] if m <= len(starts) else []
            if m >= 1 and m - 1 in out:
                theta = out[m - 1][0]
                f, zeta = np.exp(theta[: m - 1]), np.exp(theta[m - 1 :])
                kept = list(zip(f.tolist(), zeta.tolist()))
                nxt = starts[m - 1] if m <= len(starts) else (self.shortfall(f, zeta), zeta0)
                tries.append([*kept, nxt])
            fits = [self.fit(t) for t in tries]
            if fits:
                out[m] = max(fits, key=lambda r: r[1] if math.isfinite(r[1]) else -math.inf)
        return out

    def profile(self, theta: np.ndarray) -> float:
        """ln L_p at theta = (ln f_1 .. ln f_M, ln zeta_1 .. ln zeta_M)."""
        m = theta.size // 2
        f, zeta = np.exp(theta[:m]), np.exp(theta[m:])
        if np.any(zeta < ZETA_BOUNDS[0]) or np.any(zeta > ZETA_BOUNDS[1]):
            return -math.inf
        return float(-self.freqs.size * np.sum(np.log(math.pi * self.noise(f, zeta)) + 1.0))

    def fit(self, starts: list[tuple[float, float]]) -> tuple[np.ndarray, float]:
        """(theta at the maximum, ln L_p there) from `starts`, also from 3x their damping."""
        if not starts:
            return np.zeros(0), self.profile(np.zeros(0))
        best: tuple[np.ndarray, float] | None = None
        for factor in (1.0, 3.0):
            t0 = np.r_[np.log([s[0] for s in starts]), np.log([min(s[1] * factor, 0.2) for s in starts])]
            m = len(starts)
            bounds = [(math.log(self.freqs[0]), math.log(self.freqs[-1]))] * m + [tuple(map(math.log, ZETA_BOUNDS))] * m
            res = optimize.minimize(
                self._objective,
                t0,
                method="L-BFGS-B",
                bounds=bounds,
                options={"eps": 1e-7},
            )
            value = self.profile(res.x)
            if best is None or value > best[1]:
                best = (res.x, value)
        return best

    def _objective(self, theta: np.ndarray) -> float:
        value = self.profile(theta)
        return -value if math.isfinite(value) else 1e300

    def hessian(self, theta: np.ndarray) -> np.ndarray:
        """- d^2 ln L_p / d theta^2 by central differences (steps 1e-5)."""
        k = theta.size
        h = np.empty((k, k))
        step = 1e-5
        base = self.profile(theta)
        for i in range(k):
            for j in range(i, k):
                ei, ej = np.eye(k)[i] * step, np.eye(k)[j] * step
                if i == j:
                    v = (self.profile(theta + ei) - 2 * base + self.profile(theta - ei)) / step**2
                else:
                    v = (
                        self.profile(theta + ei + ej)
                        - self.profile(theta + ei - ej)
                        - self.profile(theta - ei + ej)
                        + self.profile(theta - ei - ej)
                    ) / (4 * step**2)
                h[i, j] = h[j, i] = -v
        return h


#: the least part of the record the input's longest stretch without gaps must hold
MIN_INPUT_STRETCH = 0.5


def _gap_free_input(channels: Channels) -> tuple[Channels, list[str]]:
    """The record cut to the input's longest stretch without missing values, and a note (none when
    it has none): a response is the structure's answer to the input at every instant, so a gap in
    the input cannot be filled (zeros would be a force that was not there). DataError when that
    stretch is under MIN_INPUT_STRETCH of the record."""
    good = np.isfinite(channels.values[:, channels.index(channels.inputs[0])])
    if good.all():
        return channels, []
    edges = np.flatnonzero(np.diff(np.r_[0, good.astype(np.int8), 0]))
    starts, stops = edges[::2], edges[1::2]
    if starts.size == 0:
        raise DataError(f"channels {channels.source}: the input {channels.inputs[0]} has no values")
    k = int(np.argmax(stops - starts))
    a, b = int(starts[k]), int(stops[k])
    n = good.size
    if b - a < MIN_INPUT_STRETCH * n:
        raise DataError(
            f"channels {channels.source}: the input {channels.inputs[0]} has {int((~good).sum())} missing values and "
            f"its longest stretch without them is {b - a} of {n} samples; input-output identification needs a "
            f"stretch of at least {MIN_INPUT_STRETCH:.0%} of the record"
        )
    cut = channels.rows(a, b)
    note = (
        f"the input {channels.inputs[0]} has {int((~good).sum())} missing values: fitted on its longest stretch "
        f"without them, {cut.time[0]:.6g}-{cut.time[-1]:.6g} s ({(b - a) / n:.0%} of the record)"
    )
    return cut, [note]


def _frf_peaks(freqs: np.ndarray, gain: np.ndarray, coherence: np.ndarray, count: int | None) -> list[Peak]:
    """(f, zeta) starts: peaks of the FRF magnitude where the coherence is high, via the singular-value
    peak picker (`vibinverse.oma.peaks.pick_peaks`)."""
    masked = np.where(coherence >= MIN_COHERENCE, gain, np.min(gain))
    sv = SingularValues(freqs, masked[:, None], np.ones((freqs.size, 1)), 1)
    return pick_peaks(sv, 1.0 / (freqs[1] - freqs[0]), count, FRF_PROMINENCE)


def identify_io(
    channels: Channels,
    *,
    modes: int | None = None,
    quantity: str | None = None,
    band: tuple[float, float] | None = None,
    seed: int = 0,
) -> OmaResult:
    """Modes from the responses given the one measured input (module docstring); arguments as
    `vibinverse.oma.identify.identify`."""
    t0 = time.perf_counter()
    responses = channels.responses
    if not responses:
        raise DataError(f"channels {channels.source}: every channel is a measured input; give at least one response")
    if len(channels.inputs) != 1:
        raise InputError(f"inputs: input-output identification takes one measured input; given {len(channels.inputs)}")
    if modes is not None and not 1 <= modes <= MAX_BANDS * MAX_MODES_PER_BAND:
        raise InputError(f"modes: must be in [1, {MAX_BANDS * MAX_MODES_PER_BAND}], got {modes}")
    resp = channels.select(list(responses))
    quantity = quantity or quantity_of(resp.units)
    if quantity not in QUANTITY_POWER:
        raise InputError(f"quantity: {quantity!r} is not one of {', '.join(QUANTITY_POWER)}")
    power = QUANTITY_POWER[quantity]
    channels, cut = _gap_free_input(channels)
    dt, notes = step_of(channels)
    notes += cut
    both = channels.select([channels.inputs[0], *responses])
    v, gap_notes = detrended(both)
    notes = notes + gap_notes
    n = v.shape[0]
    spec = np.fft.rfft(v, axis=0) * math.sqrt(dt / n)
    j = np.arange(1, (n - 1) // 2 + 1)
    freqs = j / (n * dt)
    force, y = spec[j, 0], spec[j, 1:]
    nyq = 0.5 / dt
    if band is not None and not (0 <= band[0] < band[1] <= nyq):
        raise InputError(f"band: need 0 <= lo < hi <= Nyquist {nyq:g} Hz, got {band[0]:g}-{band[1]:g}")
    # Welch H1 and coherence for the band picking
    nper = max(16, min(n // 8, n))
    fw, pff = signal.welch(v[:, 0], fs=1.0 / dt, nperseg=nper)
    _, pfy = signal.csd(v[:, :1], v[:, 1:], fs=1.0 / dt, nperseg=nper, axis=0)
    _, pyy = signal.welch(v[:, 1:], fs=1.0 / dt, nperseg=nper, axis=0)
    keep = fw > 0
    if band is not None:
        keep &= (fw >= band[0]) & (fw <= band[1])
    h1 = np.abs(pfy[keep]) / np.maximum(pff[keep, None], 1e-300)
    coh = np.abs(pfy[keep]) ** 2 / np.maximum(pff[keep, None] * pyy[keep], 1e-300)
    gain = np.sqrt((h1**2).sum(axis=1))
    starts = _frf_peaks(fw[keep], gain, np.median(coh, axis=1), modes)
    rng = np.random.default_rng(seed)
    found: list[OmaMode] = []
    fits: list[BandFit] = []
    resolution = 1.0 / (n * dt)
    for lo, hi, group in group_bands(starts, resolution, nyq):
        sel = (freqs >= lo) & (freqs <= hi)
        if sel.sum() < 8:
            continue
        io = IOBand(freqs[sel], y[sel], force[sel], power)
        st = [(p.f, p.zeta) for p in sorted(group, key=lambda p: -p.prominence)]  # the strongest first
        counts = [len(st)] if modes is not None else list(range(min(len(st) + 1, MAX_MODES_PER_BAND) + 1))
        nobs = 2 * int(sel.sum()) * y.shape[1]
        orders: dict[int, dict] = {}
        best = None
        for m, (theta, ll) in io.orders(st, counts).items():
            if not math.isfinite(ll):
                continue
            k = 2 * m + (3 * m + 2) * y.shape[1] + y.shape[1]
            bic = -2.0 * ll + k * math.log(nobs)
            fm, zm = np.exp(theta[:m]), np.exp(theta[m:])
            # broad "modes" are the FRF's shape, sub-resolution ones a spike; two modes within two
            # ordinates are one mode split into a cancelling pair
            apart = bool(np.all(np.diff(np.sort(fm)) > 2 * resolution))
            ok = bool(np.all(zm <= 0.1)) and bool(np.all(2 * zm * fm >= resolution)) and apart
            orders[m] = {
                "bic": bic,
                "log_likelihood": ll,
                "frequencies": fm.tolist(),
                "damping_ratios": zm.tolist(),
                "eligible": ok,
            }
            if ok and (best is None or bic < best[0]):
                best = (bic, theta)
        if best is None:
            continue
        theta = best[1]
        m = theta.size // 2
        fits.append(BandFit(float(lo), float(hi), int(sel.sum()), orders, m))
        if m == 0:
            continue
        f, zeta = np.exp(theta[:m]), np.exp(theta[m:])
        coef, noise, cov_a = io.solve(f, zeta)
        warn: list[str] = []
        try:
            cov_t = np.linalg.inv(io.hessian(theta))
            good = bool(np.all(np.linalg.eigvalsh(cov_t) > 0))
        except np.linalg.LinAlgError:
            good = False
        draws_t = rng.multivariate_normal(theta, cov_t, size=DRAWS) if good else theta[None, :]
        if not good:
            warn.append("the profile likelihood is not locally Gaussian at its maximum: no interval")
        for k in range(m):
            fd, zd = np.exp(draws_t[:, k]), np.exp(draws_t[:, m + k])
            a = coef[k]
            # residues given (f, zeta): each channel's least-squares sd, sqrt(n_c / 2 (X^T X)^-1_kk)
            sd_a = np.sqrt(np.maximum(cov_a[k, k] * noise / 2.0, 0.0))
            ad = a[None, :] + rng.normal(size=(DRAWS, a.size)) * sd_a[None, :]
            shape = signed_unit(a)
            ref = int(np.argmax(np.abs(a)))
            ud = ad / np.linalg.norm(ad, axis=1, keepdims=True)
            ud *= np.sign(ud[:, ref] * shape[ref])[:, None]
            found.append(
                mode_from_draws(f[k], zeta[k], shape, (fd, zd, ud), (lo, hi), float(np.linalg.norm(a)), warn, good)
            )
    found.sort(key=lambda m: m.frequency)
    notes.append(f"input-output: the responses fitted given the measured input {channels.inputs[0]}")
    if not found:
        notes.append("no mode found: no band's evidence favoured a mode over the residual terms and noise")
    return OmaResult(
        modes=found,
        names=resp.names,
        units=resp.units,
        quantity=quantity,
        bands=fits,
        sv_freqs=fw[keep],
        sv_values=gain[:, None],
        samples=n,
        fs=1.0 / dt,
        seconds=time.perf_counter() - t0,
        search=(float(band[0]), float(band[1])) if band is not None else (0.0, nyq),
        notes=notes,
        method="input-output (profile likelihood of the responses given the input, in bands) + Laplace",
        spectrum="|H1| (frequency response magnitude over the responses)",
    )

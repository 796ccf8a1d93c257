"""The robustness bench's peers (`vibinverse.bench.robustness_bench`): two other ways to fit
modes and lines to one series, each a `Fitter` that returns a `FitOutcome`:

- celerite2 (`Celerite2Fitter`): a Gaussian process with one SHO term per mode, a low-frequency
  SHO term (Q = 1/sqrt 2, corner at one cycle per record) for drift and a jitter, and a mean of
  a level plus one sinusoid per line; "celerite2-ou" adds an Ornstein-Uhlenbeck term (RealTerm)
  for coloured sensor noise, the structure ours-fixed has. MAP by scipy (L-BFGS-B, the noise
  terms first, the mean's linear coefficients profiled out by generalized least squares) from
  periodogram starts (every assignment of the highest and the most prominent peaks to modes and
  lines, screened), 90 % intervals from the Laplace approximation (numerical Hessian of the full
  log-likelihood, over the parameters off their bounds), every component tested by the
  log-likelihood ratio of the fit without it (the threshold of `vibinverse.detection`:
  12.5 + ln(band x span)). Irregular stamps are native to a GP; gaps are dropped;
- SSI-cov (`SSIFitter`): pyOMA2's covariance-driven stochastic subspace identification on the
  single channel, uniform stamps only (gaps and irregular stamps resampled onto the nominal grid by
  linear interpolation), linear trend removed, decimated to <= 50 Hz, 50 block rows, orders up to
  40; the mode-shape hard criteria (undefined on one channel) off. A pole is stable by pyOMA2's
  soft criteria (frequency within 5 %, damping within 10 % of a pole of the previous order) with a
  floor of 0.002 on the damping change, so that a line's near-zero damping can be stable; the
  modes are the clusters of stable poles present in at least 40 % of the model orders; a cluster
  with damping ratio below 0.3 % is reported as a line (its amplitude by least squares at that
  frequency); no intervals.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from vibinverse.bench.robustness_fit import FitOutcome, detection_threshold, failed_outcome, quiet

LINE_DAMPING = 0.003  # SSI: a stable pole cluster less damped than this is a line


# ------------------------------------------------------------------ the celerite2 peer


def periodogram(t: np.ndarray, y: np.ndarray, fmin: float, fmax: float, oversample: int = 5):
    """(frequencies, power) of the floating-mean Lomb-Scargle periodogram (nifty-ls), on a grid of
    1 / (oversample x span)."""
    import nifty_ls

    span = float(t[-1] - t[0])
    nf = max(8, int((fmax - fmin) * span * oversample))
    res = nifty_ls.lombscargle(t, np.ascontiguousarray(y), fmin=fmin, fmax=fmax, Nf=nf, normalization="psd")
    return res.freq(), res.power


def spectral_peaks(
    freqs: np.ndarray, power: np.ndarray, n: int, span: float, smooth: int = 5, prominence: bool = False
) -> list[float]:
    """The `n` highest peaks of the periodogram smoothed over `smooth` bins (`prominence`: ranked
    by their height over the running median of the periodogram over 1 Hz or 40 resolution bins,
    whichever is wider, so that a peak stands out of coloured noise), each at least 3 resolution
    bins (3 / span) and 3 % of its frequency from every one ranked above it, placed at the raw
    maximum within the smoothing window."""
    from scipy.ndimage import median_filter
    from scipy.signal import find_peaks

    sm = np.convolve(power, np.ones(smooth) / smooth, mode="same")
    rank = sm
    if prominence:
        df = float(freqs[1] - freqs[0])
        width = min(power.size, max(int(1.0 / df), int(40.0 / span / df))) | 1
        rank = sm / np.maximum(median_filter(power, size=width, mode="nearest"), 1e-300)
    idx, _ = find_peaks(sm)
    out: list[float] = []
    for i in idx[np.argsort(rank[idx])[::-1]]:
        lo, hi = max(0, i - smooth), min(power.size, i + smooth + 1)
        f = float(freqs[lo + int(np.argmax(power[lo:hi]))])
        if all(abs(f - g) > max(3.0 / span, 0.03 * g) for g in out):
            out.append(f)
        if len(out) == n:
            break
    return out


@dataclass
class _Spec:
    """The components of one GP fit: each mode's start (frequency, damping ratio, rms), each line's
    start frequency."""

    modes: list[tuple[float, float, float]]
    lines: list[float]


@dataclass
class Celerite2Fitter:
    """The celerite2 peer (module docstring): SHO terms, a drift term, a jitter and a sinusoid mean
    per line (`red_noise`: also an Ornstein-Uhlenbeck term, `celerite2.terms.RealTerm`, for AR(1)
    sensor noise, as ours-fixed has). Every assignment of the K + L + `extra_peaks` strongest
    periodogram peaks to K modes and L lines is screened by its log-likelihood at its start, the
    best `screen` optimized for `screen_iter` iterations, the best `max_starts` of those to the
    MAP, the best optimum kept; Laplace intervals; likelihood-ratio detection of every component."""

    name: str = "celerite2"
    drift: bool = True
    red_noise: bool = False
    max_starts: int = 2
    screen: int = 4
    screen_iter: int = 15
    extra_peaks: int = 3
    max_iter: int = 300
    _cache: tuple | None = field(default=None, init=False, repr=False, compare=False)

    # -- the model: theta = per mode (log f, log zeta, log rms), per line (f - start) x span,
    #    the drift's rms / sd (linear, so that no drift is a bound reached at once), the red
    #    noise's rms / sd and log correlation time, log jitter; the mean (level, cos and sin per
    #    line) is linear
    def _unpack(self, theta: np.ndarray, spec: _Spec, span: float, sd: float):
        k, m = len(spec.modes), len(spec.lines)
        modes = [(math.exp(theta[3 * i]), math.exp(theta[3 * i + 1]), math.exp(theta[3 * i + 2])) for i in range(k)]
        lines = [spec.lines[j] + float(theta[3 * k + j]) / span for j in range(m)]
        rest = list(theta[3 * k + m :])
        drift = float(rest.pop(0)) * sd if self.drift else None
        red = (float(rest.pop(0)) * sd, math.exp(rest.pop(0))) if self.red_noise else None
        return modes, lines, (drift, red), math.exp(rest[-1])

    def _gp(self, theta, spec, t, span, sd):
        import celerite2
        from celerite2 import terms

        modes, lines, (drift, red), jitter = self._unpack(theta, spec, span, sd)
        parts = [terms.SHOTerm(sigma=rms, w0=2 * math.pi * f, Q=0.5 / zeta) for f, zeta, rms in modes]
        if red and red[0] > 0:
            parts.append(terms.RealTerm(a=red[0] ** 2, c=1.0 / red[1]))
        if drift:
            # a critically damped (Q = 1/sqrt 2) term with its corner at one cycle per record
            parts.append(terms.SHOTerm(sigma=drift, w0=2 * math.pi / span, Q=1.0 / math.sqrt(2.0)))
        if not parts:  # white noise alone: a negligible term keeps celerite2 happy
            parts.append(terms.RealTerm(a=1e-12 * sd**2, c=1.0))
        kernel = parts[0]
        for p in parts[1:]:
            kernel = kernel + p
        gp = celerite2.GaussianProcess(kernel, mean=0.0)
        gp.compute(t, diag=np.full(t.size, jitter**2), check_sorted=False)
        return gp, lines

    def _design(self, t: np.ndarray, lines: list[float]) -> np.ndarray:
        key = (id(t), tuple(lines))
        if self._cache is None or self._cache[0] != key:
            cols = [np.ones_like(t)]
            for f in lines:
                cols += [np.cos(2 * np.pi * f * t), np.sin(2 * np.pi * f * t)]
            self._cache = (key, np.column_stack(cols + [np.zeros_like(t)]))
        return self._cache[1]

    def _profiled(self, theta, spec, t, y, span, sd) -> tuple[float, np.ndarray]:
        """(-log L maximized over the mean's linear coefficients (generalized least squares), those
        coefficients)."""
        try:
            gp, lines = self._gp(theta, spec, t, span, sd)
            xy = self._design(t, lines).copy()
            xy[:, -1] = y
            kxy = gp.apply_inverse(xy)
            x, kx, ky = xy[:, :-1], kxy[:, :-1], kxy[:, -1]
            b = x.T @ ky
            beta = np.linalg.solve(x.T @ kx, b)
            norm = getattr(gp, "_norm", None)
            if norm is None:  # pragma: no cover - another celerite2 layout
                val = -float(gp.log_likelihood(y - x @ beta))
            else:
                val = -(float(norm) - 0.5 * float(y @ ky - b @ beta))
        except (np.linalg.LinAlgError, ValueError, RuntimeError, OverflowError, ZeroDivisionError):
            return 1e25, np.zeros(1 + 2 * len(spec.lines))
        return (val if math.isfinite(val) else 1e25), beta

    def _full(self, phi, spec, t, y, span, sd, n_theta) -> float:
        """log L of theta and the mean's coefficients together (the Laplace approximation's)."""
        try:
            gp, lines = self._gp(phi[:n_theta], spec, t, span, sd)
            val = float(gp.log_likelihood(y - self._design(t, lines)[:, :-1] @ phi[n_theta:]))
        except (np.linalg.LinAlgError, ValueError, RuntimeError, OverflowError, ZeroDivisionError):
            return -1e25
        return val if math.isfinite(val) else -1e25

    def _bounds(self, spec, span, sd, nyq):
        b = []
        for _ in spec.modes:
            b += [(math.log(3.0 / span), math.log(nyq)), (math.log(1e-4), math.log(0.5))]
            b += [(math.log(1e-4 * sd), math.log(10 * sd))]
        b += [(-3.0, 3.0)] * len(spec.lines)
        if self.drift:
            b += [(0.0, 10.0)]
        if self.red_noise:
            b += [(0.0, 10.0), (math.log(0.1 / nyq), math.log(span))]
        b += [(math.log(1e-4 * sd), math.log(10 * sd))]
        return b

    def _start(self, spec, span, sd, drift_sd, jitter, nyq):
        th = []
        for f, zeta, rms in spec.modes:
            th += [math.log(f), math.log(zeta), math.log(rms)]
        th += [0.0] * len(spec.lines)
        if self.drift:
            th += [max(drift_sd / sd, 0.05)]
        if self.red_noise:
            th += [0.3, math.log(2.5 / nyq)]  # rms 0.3 sd, correlation time 5 samples
        th += [math.log(jitter)]
        return np.array(th)

    def _map(self, spec, t, y, span, sd, nyq, x0, max_iter=None, staged=True):
        """L-BFGS-B from x0; `staged`: the noise terms (drift, red noise, jitter) first with the
        modes and lines held at x0, so that the first steps of the full search do not trade a
        mode for noise that has not yet been fitted."""
        from scipy.optimize import minimize

        bounds = self._bounds(spec, span, sd, nyq)
        x = np.clip(x0, [b[0] + 1e-9 for b in bounds], [b[1] - 1e-9 for b in bounds])
        nll = lambda th: self._profiled(th, spec, t, y, span, sd)[0]
        first = 3 * len(spec.modes) + len(spec.lines)
        if staged and first:
            res = minimize(
                lambda th: nll(np.concatenate([x[:first], th])),
                x[first:],
                method="L-BFGS-B",
                bounds=bounds[first:],
                options={"maxiter": 50},
            )
            x = np.concatenate([x[:first], res.x])
        res = minimize(nll, x, method="L-BFGS-B", bounds=bounds, options={"maxiter": max_iter or self.max_iter})
        return res.x, float(res.fun)

    def fit(self, t: np.ndarray, y: np.ndarray, order: tuple[int, int] | None = None) -> FitOutcome:
        t0 = time.perf_counter()
        try:
            with quiet():
                out = self._fit(t, y, order or (1, 1))
        except Exception as exc:  # noqa: BLE001 - a failed fit is a result of the bench
            return failed_outcome(t0, exc)
        out.seconds = time.perf_counter() - t0
        return out

    def _starts(self, t, y, k, m, span, nyq):
        """Candidate specs (every assignment to K modes and L lines of the K + L + `extra_peaks`
        highest and as many most prominent periodogram peaks), the drift's and the jitter's start."""
        lo = 3.0 / span
        u = t / span - 0.5
        trend = np.polyval(np.polyfit(u, y, 2), u)
        z = y - trend
        freqs, power = periodogram(t, z, lo, 0.95 * nyq)
        # candidates: the highest peaks and the most prominent ones (over coloured noise)
        peaks = spectral_peaks(freqs, power, k + m + self.extra_peaks, span)
        for f in spectral_peaks(freqs, power, k + m + self.extra_peaks, span, prominence=True):
            if all(abs(f - g) > max(3.0 / span, 0.03 * g) for g in peaks):
                peaks.append(f)
        while len(peaks) < k + m + self.extra_peaks:
            peaks.append(lo + (0.9 * nyq - lo) * (len(peaks) + 1) / (k + m + self.extra_peaks + 1))
        var, floor = float(np.var(z)), float(np.median(power))
        as_mode = [_mode_start(freqs, power, f, span, floor, var) for f in peaks]
        as_line = [_line_start(t, z, f, span) if m else f for f in peaks]
        specs = []
        for li in itertools.combinations(range(len(peaks)), m):
            rest = [i for i in range(len(peaks)) if i not in li]
            for mi in itertools.combinations(rest, k):
                specs.append(_Spec(sorted(as_mode[i] for i in mi), sorted(as_line[i] for i in li)))
        return specs, float(np.std(trend)), math.sqrt(0.5 * var)

    def _fit(self, t, y, order) -> FitOutcome:
        ok = np.isfinite(y)
        t, y = np.asarray(t, float)[ok], np.asarray(y, float)[ok]
        t = t - t[0]
        span = float(t[-1])
        nyq = 0.5 / float(np.median(np.diff(t)))
        sd = float(np.std(y))
        k, m = order
        specs, drift_sd, jitter = self._starts(t, y, k, m, span, nyq)
        screened = []
        for spec in specs:
            x0 = self._start(spec, span, sd, drift_sd, jitter, nyq)
            screened.append((self._profiled(x0, spec, t, y, span, sd)[0], spec, x0))
        screened.sort(key=lambda s: s[0])
        # the best `screen` starts a few iterations each, then the best `max_starts` to the end
        short = []
        for _, spec, x0 in screened[: self.screen if k and m else 2]:  # no line-or-mode ambiguity: 2
            theta, val = self._map(spec, t, y, span, sd, nyq, x0, self.screen_iter)
            short.append((val, spec, theta))
        short.sort(key=lambda s: s[0])
        best = None
        for _, spec, x0 in short[: self.max_starts if k and m else 1]:
            theta, val = self._map(spec, t, y, span, sd, nyq, x0)
            if best is None or val < best[2]:
                best = (spec, theta, val)
        spec, theta, val = best
        _, beta = self._profiled(theta, spec, t, y, span, sd)
        modes, lines, _, _ = self._unpack(theta, spec, span, sd)
        n_theta = theta.size
        phi = np.concatenate([theta, beta])
        steps = np.concatenate([np.full(n_theta, 1e-3), np.full(beta.size, 1e-3 * sd)])
        steps[3 * k : 3 * k + m] = 0.01  # line offsets, in units of 1 / span
        # the Laplace approximation over the parameters off their bounds (a term fitted to nothing,
        # at its lower bound, has no curvature there and no interval is asked of it)
        bounds = self._bounds(spec, span, sd, nyq)
        free = [i for i in range(n_theta) if bounds[i][0] + 1e-3 < theta[i] < bounds[i][1] - 1e-3]
        free += list(range(n_theta, phi.size))
        sub = _laplace(lambda p: self._full(_put(phi, free, p), spec, t, y, span, sd, n_theta), phi[free], steps[free])
        cov = None
        if sub is not None:
            cov = np.full((phi.size, phi.size), np.nan)
            cov[np.ix_(free, free)] = sub
        out = FitOutcome(
            frequencies=[f for f, _, _ in modes],
            damping_ratios=[z for _, z, _ in modes],
            line_frequencies=[float(f) for f in lines],
            line_amplitudes=[float(np.hypot(beta[1 + 2 * j], beta[2 + 2 * j])) for j in range(m)],
        )
        if cov is not None:
            _intervals(out, cov, theta, beta, lines, k, m, span)
        # likelihood-ratio test of each component: the fit without it, from the MAP's other values
        limit = detection_threshold(nyq - 3.0 / span, span)
        for i in range(k):
            sub = _Spec(spec.modes[:i] + spec.modes[i + 1 :], spec.lines)
            x0 = np.delete(theta, [3 * i, 3 * i + 1, 3 * i + 2])
            out.modes_detected.append(self._map(sub, t, y, span, sd, nyq, x0, 100, staged=False)[1] - val > limit)
        for j in range(m):
            sub = _Spec(spec.modes, spec.lines[:j] + spec.lines[j + 1 :])
            x0 = np.delete(theta, 3 * k + j)
            out.lines_detected.append(self._map(sub, t, y, span, sd, nyq, x0, 100, staged=False)[1] - val > limit)
        return out


def _put(x: np.ndarray, idx: list[int], values: np.ndarray) -> np.ndarray:
    out = x.copy()
    out[idx] = values
    return out


def _intervals(out: FitOutcome, cov, theta, beta, lines, k, m, span) -> None:
    """90 % Laplace intervals (where the parameter has a variance: off its bounds): the modes' in
    log space, the lines' frequencies linear, their amplitudes by the delta method on the (cos,
    sin) coefficients."""
    n_theta = theta.size
    for i in range(k):
        for name, col in (("frequency", 3 * i), ("damping_ratio", 3 * i + 1)):
            if np.isfinite(cov[col, col]):
                half = 1.645 * math.sqrt(cov[col, col])
                lo, hi = (math.exp(min(theta[col] + d, 700.0)) for d in (-half, half))  # a flat one: huge
                out.intervals[f"modes[{i}].{name}"] = (lo, hi)
    for j in range(m):
        c = 3 * k + j
        if np.isfinite(cov[c, c]):
            half = 1.645 * math.sqrt(cov[c, c]) / span
            out.intervals[f"lines[{j}].frequency"] = (lines[j] - half, lines[j] + half)
        a, b = beta[1 + 2 * j], beta[2 + 2 * j]
        amp = math.hypot(a, b)
        g = np.array([a, b]) / max(amp, 1e-300)
        ia = n_theta + 1 + 2 * j
        sd_a = math.sqrt(max(float(g @ cov[ia : ia + 2, ia : ia + 2] @ g), 0.0))
        out.intervals[f"lines[{j}].amplitude"] = (max(amp - 1.645 * sd_a, 0.0), amp + 1.645 * sd_a)


def _mode_start(freqs, power, f, span, floor, var) -> tuple[float, float, float]:
    """(frequency, damping ratio, rms) of a mode at a periodogram peak: damping 0.02 (a raw
    periodogram's half-power width is too noisy to tell), the power above the floor within the
    peak's band (3 resolution bins, or 3 half-power widths of the smoothed peak) as its share of
    the variance."""
    sm = np.convolve(power, np.ones(5) / 5, mode="same")
    i = int(np.argmin(np.abs(freqs - f)))
    half = floor + 0.5 * max(sm[i] - floor, 0.0)
    lo = hi = i
    while lo > 0 and sm[lo] > half:
        lo -= 1
    while hi < sm.size - 1 and sm[hi] > half:
        hi += 1
    width = float(freqs[hi] - freqs[lo])
    band = np.abs(freqs - f) <= max(3.0 / span, 3.0 * width)
    share = float(np.clip(np.sum(np.clip(power[band] - floor, 0.0, None)) / np.sum(power), 0.02, 0.9))
    return float(f), 0.02, math.sqrt(share * var)


def _line_start(t, z, f, span) -> float:
    """The frequency within one resolution bin of `f` where a least-squares sinusoid fits best."""
    best, val = f, -1.0
    for g in np.linspace(f - 0.5 / span, f + 0.5 / span, 21):
        c, s = np.cos(2 * np.pi * g * t), np.sin(2 * np.pi * g * t)
        power = (c @ z) ** 2 / (c @ c) + (s @ z) ** 2 / (s @ s)
        if power > val:
            best, val = float(g), power
    return best


def _laplace(loglike: Callable[[np.ndarray], float], x: np.ndarray, steps: np.ndarray) -> np.ndarray | None:
    """The covariance inv(-H) of the Laplace approximation at x (H by central differences with
    `steps`), or None when -H is not positive definite."""
    n = x.size
    f0 = loglike(x)
    h = np.zeros((n, n))
    e = np.eye(n) * steps
    for a in range(n):
        h[a, a] = (loglike(x + e[a]) - 2 * f0 + loglike(x - e[a])) / steps[a] ** 2
        for b in range(a):
            pp, pm = loglike(x + e[a] + e[b]), loglike(x + e[a] - e[b])
            mp, mm = loglike(x - e[a] + e[b]), loglike(x - e[a] - e[b])
            h[a, b] = h[b, a] = (pp - pm - mp + mm) / (4 * steps[a] * steps[b])
    try:
        np.linalg.cholesky(-h)
        cov = np.linalg.inv(-h)
    except np.linalg.LinAlgError:
        return None
    return cov if np.all(np.isfinite(cov)) else None


# ------------------------------------------------------------------ the SSI peer


@dataclass
class SSIFitter:
    """pyOMA2's SSI-cov on the single channel (module docstring)."""

    name: str = "ssi-cov"
    block_rows: int = 50  # > max_order: one channel's Hankel matrix has block_rows rows
    max_order: int = 40
    target_fs: float = 50.0
    min_share: float = 0.4
    err_fn: float = 0.05  # pyOMA2's soft criteria (its defaults) ...
    err_xi: float = 0.1
    xi_floor: float = 0.002  # ... with a floor on the damping change: a line's ~0 damping can be stable

    def fit(self, t: np.ndarray, y: np.ndarray, order: tuple[int, int] | None = None) -> FitOutcome:
        t0 = time.perf_counter()
        try:
            with quiet():
                out = self._fit(np.asarray(t, float), np.asarray(y, float))
        except Exception as exc:  # noqa: BLE001 - a failed fit is a result of the bench
            return failed_outcome(t0, exc)
        out.seconds = time.perf_counter() - t0
        return out

    def _fit(self, t: np.ndarray, y: np.ndarray) -> FitOutcome:
        from pyoma2.algorithms import SSI
        from pyoma2.setup import SingleSetup
        from scipy.signal import decimate, detrend

        ok = np.isfinite(y)
        dt = float(np.median(np.diff(t)))
        span = float(t[-1] - t[0])
        grid = t[0] + np.arange(round(span / dt) + 1) * dt
        note = ""
        if not ok.all() or grid.size != t.size or np.abs(grid - t).max() > 1e-9 * dt:
            note = "resampled onto the nominal grid by linear interpolation"
        yu = detrend(np.interp(grid, t[ok], y[ok]))
        fs = 1.0 / dt
        q = max(1, int(fs // self.target_fs))
        if q > 1:
            yu, fs = decimate(yu, q, ftype="fir", zero_phase=True), fs / q
        setup = SingleSetup(yu[:, None], fs=fs)
        # one channel: the mode-shape criteria (MPC, MPD) are undefined, only the damping bound applies
        hc = {"xi_max": 0.2, "mpc_lim": None, "mpd_lim": None, "CoV_max": None}
        alg = SSI(name="ssi", method="cov", br=self.block_rows, ordmax=self.max_order, calc_unc=False, hc=hc)
        setup.add_algorithms(alg)
        setup.run_by_name("ssi")
        res = alg.result
        fn, xi = np.asarray(res.Fn_poles, float), np.asarray(res.Xi_poles, float)
        lab = stability_labels(fn, xi, self.err_fn, self.err_xi, self.xi_floor)
        clusters = stable_clusters(fn, xi, lab, self.min_share, lo=3.0 / span, hi=0.45 * fs)
        out = FitOutcome(note=note)
        for f, z in clusters:
            if z < LINE_DAMPING:
                out.line_frequencies.append(f)
                out.line_amplitudes.append(_ls_amplitude(t[ok], y[ok], f))
                out.lines_detected.append(True)
            else:
                out.frequencies.append(f)
                out.damping_ratios.append(z)
                out.modes_detected.append(True)
        return out


def stability_labels(fn: np.ndarray, xi: np.ndarray, err_fn: float, err_xi: float, xi_floor: float) -> np.ndarray:
    """1 where a pole (row) of model order (column) has a pole at the previous order within
    `err_fn` relative in frequency and within max(`err_xi` relative, `xi_floor`) in damping ratio
    (pyOMA2's soft criteria without the mode-shape one, trivial on one channel, plus the floor)."""
    lab = np.zeros(fn.shape, int)
    for o in range(1, fn.shape[1]):
        prev_f, prev_x = fn[:, o - 1], xi[:, o - 1]
        good = np.isfinite(prev_f)
        if not good.any():
            continue
        prev_f, prev_x = prev_f[good], prev_x[good]
        for i in np.flatnonzero(np.isfinite(fn[:, o])):
            j = int(np.argmin(np.abs(prev_f - fn[i, o])))
            df = abs(fn[i, o] - prev_f[j]) / fn[i, o]
            dx = abs(xi[i, o] - prev_x[j])
            if df < err_fn and dx < max(err_xi * abs(xi[i, o]), xi_floor):
                lab[i, o] = 1
    return lab


def stable_clusters(
    fn: np.ndarray, xi: np.ndarray, lab: np.ndarray, min_share: float, lo: float, hi: float, tol: float = 0.01
) -> list[tuple[float, float]]:
    """(frequency, damping ratio) medians of the clusters of stable poles (label 1) of a
    stabilization diagram (pole, order arrays): poles sorted by frequency, split where neighbours
    differ by more than `tol` relative; kept when the cluster has stable poles in at least
    `min_share` of the orders that have any pole."""
    sel = (lab == 1) & np.isfinite(fn) & (fn > lo) & (fn < hi)
    if not sel.any():
        return []
    orders = np.broadcast_to(np.arange(fn.shape[1]), fn.shape)[sel]
    f, z = fn[sel], xi[sel]
    n_orders = int(np.sum(np.any(np.isfinite(fn), axis=0)))
    idx = np.argsort(f)
    f, z, orders = f[idx], z[idx], orders[idx]
    splits = np.flatnonzero(np.diff(f) / f[:-1] > tol) + 1
    out = []
    for cf, cz, co in zip(np.split(f, splits), np.split(z, splits), np.split(orders, splits)):
        if np.unique(co).size >= min_share * n_orders:
            out.append((float(np.median(cf)), float(np.median(cz))))
    return out


def _ls_amplitude(t: np.ndarray, y: np.ndarray, f: float) -> float:
    x = np.column_stack([np.ones_like(t), t - t.mean(), np.cos(2 * np.pi * f * t), np.sin(2 * np.pi * f * t)])
    beta = np.linalg.lstsq(x, y, rcond=None)[0]
    return float(np.hypot(beta[2], beta[3]))

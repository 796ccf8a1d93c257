"""SINDy identification of the roof's tilt-mode equation (pysindy), made noise-robust by working on
the correlation function.

The tilt coordinate obeys q'' + 2 zeta w q' + w^2 q = drive lines + white base forcing (eqs.
(11)-(16), linearized). Read at first order, the pixel's AC signal is a scaled copy of q plus
white sensor noise. Differentiating that signal twice would let the sensor noise dominate (and
bias w^2 towards the noise's mean square frequency). Instead:

1. The drive lines (frequencies from the spectral stage) are removed as fitted sinusoids.
2. The residual is band-limited around the spectral resonance guess, and its autocovariance R(tau)
   for lags tau > 0 is formed. For a mode driven by white forcing, R obeys the free equation
   R'' + 2 zeta w R' + w^2 R = 0 (the "natural excitation technique", James, Carne & Lauffer 1993),
   and white sensor noise enters only at tau = 0, which is left out.
3. SINDy (sequentially thresholded least squares) identifies R' and R'' from a library of
   polynomials in (R, R') up to degree 2 with a constant, in units where the resonance period is
   1. Columns are normalized, so the threshold (0.4 % of R'') acts on each term's contribution;
   the damping term carries ~2 zeta (3 % at the paper's roof) and stays. The library is linear
   plus a constant (the physics is linear; degree 2 let sensor noise through as R^2 and R R' terms
   of ~0.4 % that no threshold separates from a light damping). The constant absorbs the
   correlation estimate's small offset. A damping below the threshold is declined as unresolved.
4. A leave-one-quarter-out jackknife of the correlation function gives the standard errors. A
   result that is not a damped oscillator, or whose frequency scatters by more than 10 %, is
   declined with the reason: never a wrong number reported with confidence.

The drive amplitude then follows through the forward model at the identified resonance (the
line's observed amplitude over the model's response per unit drive), as in the spectral stage.
"""

from __future__ import annotations

import logging
import warnings
from typing import Any, Protocol, runtime_checkable

import numpy as np
from scipy.signal import butter, sosfiltfilt

from vibinverse.errors import Unsupported
from vibinverse.estimators.base import Estimator, base_result, register_estimator
from vibinverse.io.series import Series
from vibinverse.posterior import Posterior
from vibinverse.result import FitResult

logger = logging.getLogger(__name__)

SEGMENTS = 4
MAX_REL_SD = 0.10  # jackknife scatter of the frequency above which the identification is declined
REL_THRESHOLD = 0.004  # a library term must carry >= 0.4 % of R'' (column-normalized STLSQ) to stay
# free response vs correlation function, relative rms (a true mode: 0.04-0.2; a steady line or band-passed
# noise: >= 0.35)
MAX_MISFIT = 0.3
# first/second-order ratio (`FrameModel.first_order_ratio`) below which the signal is no scaled copy of
# the modal coordinate and the correlation function no free response of the mode
MIN_FIRST_ORDER = 3.0
LIBRARY_DEGREE = 1  # [1, R, R']: the physics is linear; the constant is the candidate spurious term


class SindyFailed(RuntimeError):
    """SINDy declined: the message says why."""


@runtime_checkable
class ResonanceModel(Protocol):
    """What SINDy reads of a model: a tilt resonance in state-space form seen through a pixel's
    observation (the frame model)."""

    key: str

    def components(self, values: dict[str, float]) -> Any: ...

    def drive_frequencies(self, values: dict[str, float]) -> list[float]: ...

    def log_likelihood(self, values: dict[str, float]) -> float: ...

    def calibrated_guess(self, drive_frequency: float | None, resonance: tuple[float, float]) -> dict[str, float]: ...

    def resonance_values(self) -> dict[str, float]: ...

    def first_order_ratio(self, values: dict[str, float]) -> float: ...


def _autocovariance(r: np.ndarray, mask: np.ndarray, lags: int) -> np.ndarray:
    """Gap-aware autocovariance at lags 0..lags-1: sum r_t r_t+k / number of valid pairs."""
    n = r.size
    f = np.fft.rfft(np.where(mask, r, 0.0), 2 * n)
    m = np.fft.rfft(mask.astype(float), 2 * n)
    num = np.fft.irfft(np.abs(f) ** 2)[:lags]
    den = np.fft.irfft(np.abs(m) ** 2)[:lags]
    return num / np.maximum(den, 1.0)


def _identify(r_corr: np.ndarray, dt_unit: float) -> tuple[float, float, np.ndarray, list[str]]:
    """SINDy on (R, R') for lags >= 1, time in units of the guessed period: (w, zeta, coefficients
    of the R'' equation, feature names)."""
    import pysindy as ps

    tau = np.arange(1, r_corr.size) * dt_unit
    x = r_corr[1:] / np.abs(r_corr[1:]).max()
    diff = ps.SmoothedFiniteDifference(smoother_kws={"window_length": 7, "polyorder": 3})
    dx = diff(x, tau)
    ddx = diff(dx, tau)
    keep = slice(3, -3)  # ends of smoothed differences are one-sided
    state = np.stack([x, dx], axis=1)[keep]
    rate = np.stack([dx, ddx], axis=1)[keep]
    # with normalized columns a coefficient is the term's L2 contribution: threshold it against R''
    threshold = REL_THRESHOLD * float(np.linalg.norm(rate[:, 1]))
    model = ps.SINDy(
        feature_library=ps.PolynomialLibrary(degree=LIBRARY_DEGREE, include_bias=True),
        optimizer=ps.STLSQ(threshold=threshold, alpha=1e-8, normalize_columns=True),
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model.fit(state, t=tau[keep], x_dot=rate, feature_names=["R", "dR"])
    names = model.get_feature_names()
    coef = model.coefficients()[1]
    lin = {n: coef[i] for i, n in enumerate(names)}
    w2, c1 = -lin.get("R", 0.0), -lin.get("dR", 0.0)
    if w2 <= 0:
        return float("nan"), float("nan"), coef, names
    w = float(np.sqrt(w2))
    return w, float(c1 / (2 * w)), coef, names


def free_response_misfit(r_corr: np.ndarray, dt_unit: float, w: float, zeta: float) -> float:
    """Relative rms misfit of the identified equation's free response, fitted in amplitude and phase,
    to the correlation function over lags >= 1: the check that it is this mode that R shows (a
    steady sinusoid or band-passed noise is not)."""
    if not (np.isfinite(w) and np.isfinite(zeta) and 0.0 < zeta < 1.0):
        return float("nan")
    tau = np.arange(1, r_corr.size) * dt_unit
    wd = w * np.sqrt(1 - zeta**2)
    env = np.exp(-zeta * w * tau)
    basis = np.stack([env * np.cos(wd * tau), env * np.sin(wd * tau)], axis=1)
    x = r_corr[1:]
    resid = x - basis @ np.linalg.lstsq(basis, x, rcond=None)[0]
    return float(np.sqrt(np.mean(resid**2) / np.mean(x**2)))


def sindy_frame(series: Series, like: ResonanceModel, start: dict[str, float]) -> dict:
    """Identify the tilt resonance and damping ratio (and, through the forward model, the drive
    amplitude) starting from the spectral stage's `start`. Raises SindyFailed with the reason."""
    k = like.key
    if not series.uniform:
        raise SindyFailed(
            "sindy: the correlation function needs a uniform grid and the stamps are irregular; the MAP takes over"
        )
    ratio = like.first_order_ratio(start)
    if ratio < MIN_FIRST_ORDER:
        raise SindyFailed(
            f"sindy: the pixel sees the tilt mostly at second order (first/second order = {ratio:.2g}; "
            "view on the lobe centre or a symmetric footprint), so the signal is not a scaled copy of "
            "the modal coordinate; use --method casadi"
        )
    t, y = series.time, series.intensity
    mask = np.isfinite(y)
    resid = np.where(mask, y - np.nanmean(y), 0.0)
    lines = like.drive_frequencies(start)
    if lines:
        basis = np.concatenate(
            [[np.cos(2 * np.pi * f * t), np.sin(2 * np.pi * f * t)] for f in lines] + [[np.ones_like(t)]]
        ).T
        coef = np.linalg.lstsq(basis[mask], resid[mask], rcond=None)[0]
        resid = np.where(mask, resid - basis @ coef, 0.0)
    f_g = start[k + "tilt_frequency"]
    nyq = 0.5 * series.fs
    band = (f_g / 2, min(2 * f_g, 0.95 * nyq))
    if not band[0] < band[1]:
        raise SindyFailed(f"sindy: the resonance guess {f_g:g} Hz is too close to the Nyquist frequency {nyq:g} Hz")
    resid = np.where(mask, sosfiltfilt(butter(2, band, btype="band", fs=series.fs, output="sos"), resid), 0.0)
    dt = series.dt
    seg = np.array_split(np.arange(t.size), SEGMENTS)
    per_segment = min(len(s) for s in seg) * dt * f_g
    if per_segment < 5:
        raise SindyFailed(
            f"sindy: a quarter of the record holds {per_segment:.1f} periods of the resonance guess "
            f"{f_g:g} Hz; the correlation function needs >= 5"
        )
    if 1.0 / (f_g * dt) < 8:
        raise SindyFailed(f"sindy: the resonance guess {f_g:g} Hz has fewer than 8 samples per period")
    lags = int(min(10.0 / (f_g * dt), min(len(s) for s in seg) // 2))
    parts = np.array([_autocovariance(resid[s], mask[s], lags) for s in seg])
    unit = dt * f_g  # time in units of the guessed period
    w, zeta, coef, names = _identify(parts.mean(axis=0), unit)
    jack = np.array([_identify(np.delete(parts, i, axis=0).mean(axis=0), unit)[:2] for i in range(SEGMENTS)])
    # the constant may stay: it absorbs the correlation estimate's small offset (mean removal)
    nonlinear = [n for n, c in zip(names, coef) if c != 0.0 and n not in ("R", "dR", "1")]
    misfit = free_response_misfit(parts.mean(axis=0), unit, w, zeta)
    f_t = w * f_g / (2 * np.pi)
    sd = np.sqrt((SEGMENTS - 1) / SEGMENTS * ((jack - jack.mean(axis=0)) ** 2).sum(axis=0))
    sd_f = sd[0] * f_g / (2 * np.pi)
    problems = []
    if not np.isfinite(w) or not np.all(np.isfinite(jack)):
        problems.append("the identified equation is not an oscillator (w^2 <= 0)")
    elif zeta == 0.0:
        problems.append("the damping term fell below the threshold (damping ratio unresolved)")
    elif not 0.0 < zeta < 1.0:
        problems.append(f"damping ratio {zeta:.3g} outside (0, 1)")
    elif sd_f > MAX_REL_SD * f_t:
        problems.append(
            f"the frequency scatters by {sd_f / f_t:.0%} across quarters of the record (> {MAX_REL_SD:.0%})"
        )
    if nonlinear:
        problems.append(f"nonlinear terms survived thresholding ({', '.join(nonlinear)})")
    if np.isfinite(misfit) and misfit > MAX_MISFIT:
        problems.append(
            f"the identified mode's free response misses the correlation function by {misfit:.0%} "
            f"(> {MAX_MISFIT:.0%}): not a resonance"
        )
    if problems:
        raise SindyFailed("sindy: identification declined: " + "; ".join(problems))
    equation = _equation(w * f_g, 2 * zeta * w * f_g)  # time unit 1/f_g -> s
    values = dict(start)
    values[k + "tilt_frequency"] = float(f_t)
    values[k + "tilt_damping_ratio"] = float(zeta)
    refit = like.calibrated_guess(start.get(k + "drive_frequency"), (f_t, zeta))
    for n in (k + "drive_amplitude", k + "drive_phase", k + "noise_rms", "noise.sigma"):
        if n in refit:
            values[n] = refit[n]
    return {
        "values": values,
        "sd": {k + "tilt_frequency": float(sd_f), k + "tilt_damping_ratio": float(sd[1])},
        "equation": equation,
        "misfit": misfit,
    }


def _equation(w: float, c: float) -> str:
    """The identified modal equation in SI units (w in rad/s, c = 2 zeta w in 1/s)."""
    return f"q'' = -{w**2:.6g} q - {c:.4g} q' + drive lines + white forcing"


def sindy_best(series: Series, like: ResonanceModel, starts: list[dict[str, float]]) -> dict:
    """SINDy from each spectral candidate (which line is the drive and which peak the resonance),
    keeping the identification the exact likelihood prefers; SindyFailed if every one declines."""
    results, reasons = [], []
    for start in starts:
        try:
            res = sindy_frame(series, like, start)
        except SindyFailed as exc:
            reasons.append(str(exc))
            continue
        res["log_likelihood"] = like.log_likelihood(res["values"])
        results.append(res)
    if not results:
        raise SindyFailed(reasons[0] if len(set(reasons)) == 1 else "; ".join(dict.fromkeys(reasons)))
    return max(results, key=lambda r: r["log_likelihood"] if np.isfinite(r["log_likelihood"]) else -np.inf)


@register_estimator
class SindyEstimator(Estimator):
    """SINDy on the correlation function (`sindy_best`) from the spectral stage's candidates.

    The result's method is "sindy" with jackknife sds when the identification holds; when it is
    declined, the spectral start with `diagnostics["sindy"]` saying why (method "spectral"). Its
    `starts` put the identified values first, for the MAP."""

    name = "sindy"
    approximation = "jackknife"

    @staticmethod
    def covers(posterior: Posterior) -> bool:
        """Whether the model has a resonance SINDy can identify."""
        return isinstance(posterior.model, ResonanceModel)

    def estimate(self, posterior: Posterior, start: FitResult | None, **options: Any) -> FitResult:
        if not self.covers(posterior):
            raise Unsupported(
                "--method sindy: SINDy identifies a noise-driven resonance (a frame scene); this "
                "scene's motion is deterministic: use spectral, map, mcmc or auto"
            )
        if start is None:
            from vibinverse.estimators.spectral import SpectralEstimator

            start = SpectralEstimator().fit(posterior)
        priors = dict(zip(posterior.space.names, posterior.space.priors))
        model = posterior.model
        starts = start.starts or [start.point]
        try:
            res = sindy_best(posterior.series, model, [{**model.resonance_values(), **s} for s in starts])
        except SindyFailed as exc:
            logger.info("%s; continuing without it", exc)
            info = {"status": "declined", "reason": str(exc)}
            return base_result(
                posterior, "spectral", start.point, starts=starts, diagnostics={"converged": None, "sindy": info}
            )
        values = {n: priors[n].inside(res["values"].get(n, s)) for n, s in starts[0].items() if n in priors}
        sd = {n: v for n, v in res["sd"].items() if n in values}
        logger.info("sindy: %s", res["equation"])
        info = {"status": "ok", "equation": res["equation"], "misfit": res["misfit"]}
        return base_result(
            posterior, "sindy", values, sd=sd, starts=[values, *starts], diagnostics={"converged": None, "sindy": info}
        )

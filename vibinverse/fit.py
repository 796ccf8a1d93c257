"""`vibinverse fit`: spectral -> MAP (+ Laplace) -> emcee, each stage seeding the next."""

from __future__ import annotations

import math
import time
import warnings
from pathlib import Path

import numpy as np

from forward.errors import SceneError
from vibinverse.data import Series, check_resolves
from vibinverse.estimators import map_fit, mcmc
from vibinverse.estimators.spectral import frame_guesses
from vibinverse.params import Prior
from vibinverse.problem import Problem
from vibinverse.result import summarize

METHODS = ("spectral", "sindy", "casadi", "map", "mcmc", "auto")
DETECTION_GAIN = 12.5  # log-likelihood gain of 5 sigma for one added line at a known frequency


def default_free(problem_key: str, table: dict, series: Series) -> dict[str, Prior]:
    """What an analyst fits on a frame scene when the scene file has no [infer] table."""
    nyq = 0.5 * series.fs
    lo = max(0.2, 3.0 / (series.time[-1] - series.time[0]))  # at least 3 cycles in the record
    return {
        problem_key + "tilt_frequency": Prior("uniform", (lo, nyq)),
        problem_key + "tilt_damping_ratio": Prior("loguniform", (1e-3, 0.5)),
        problem_key + "drive_frequency": Prior("uniform", (lo, nyq)),
        # uniform, not log-uniform: a log-uniform prior puts half its mass on amplitudes too small
        # to see, where the drive frequency is free, and walkers drift onto that plateau
        problem_key + "drive_amplitude": Prior("uniform", (0.0, 0.05)),
        problem_key + "drive_phase": Prior("uniform", (-np.pi, np.pi)),
        problem_key + "noise_rms": Prior("loguniform", (1e-7, 1e-1)),
        "noise.sigma": Prior("loguniform", (1e-8, 1e3)),
    }


def response_free(table: dict, series: Series, like=None) -> dict[str, Prior]:
    """What an analyst fits on a deterministic scene (plate, Rayleigh source) without an [infer]
    table: each line's frequency (the whole band for one line; between the neighbours' midpoints
    for several, so that lines cannot swap), amplitude (0 to 100x the scene's value), phase (a 2 pi
    window centred on the spectral estimate, so that the posterior does not straddle the wrap; a pi
    window for a line the footprint sees only at second order, where the phase is defined mod pi), the
    calibration gain sun.irradiance (within 2x of what the data's mean level implies) and the
    sensor noise sigma."""
    from vibinverse.estimators.response_spectral import gain_from_level, response_guesses
    from vibinverse.response_model import ResponseLikelihood

    like = like or ResponseLikelihood(table, series)
    lines = like.lines()
    if not lines:
        raise SceneError("fit: the scene's motions have no frequency and amplitude to fit; give an [infer] table")
    nyq = 0.5 * series.fs
    lo = max(3.0 / (series.time[-1] - series.time[0]), 1e-6)
    f0 = sorted(like.base_value(ln.frequency) for ln in lines)
    same = [a for a, b in zip(f0, f0[1:]) if a == b]
    if same:
        raise SceneError(f"fit: two lines share the frequency {same[0]:g} Hz in the scene, so default priors cannot keep "
                         "them apart; give their frequencies priors in [infer.free] or --free")
    edges = [lo, *((a + b) / 2 for a, b in zip(f0, f0[1:])), nyq]
    free: dict[str, Prior] = {}
    for line in lines:
        f, a = like.base_value(line.frequency), like.base_value(line.amplitude)
        if not a > 0:
            raise SceneError(f"{line.amplitude}: the scene's value sets the scale of the default prior and must be > 0 "
                             "(or give the prior in [infer.free])")
        i = f0.index(f)
        free[line.frequency] = Prior("uniform", (edges[i], edges[i + 1]))
        free[line.amplitude] = Prior("uniform", (0.0, 100.0 * a))
        free[line.phase] = Prior("uniform", (-np.pi, np.pi))
    scale = float(np.nanmax(np.abs(series.intensity)))
    gain = gain_from_level(series, like)
    if gain > 0:  # (NaN when the model or the data have no positive level: the gain stays fixed)
        free["sun.irradiance"] = Prior("loguniform", (gain / 2, gain * 2))
    free["noise.sigma"] = Prior("loguniform", (max(1e-9 * scale, 1e-300), 10.0 * float(np.nanstd(series.intensity))))
    bounds = {n: p.bounds for n, p in free.items()}
    problem = Problem(table, series, free, like=like)
    guesses = [{n: _inside(g.get(n, _prior_centre(free[n])), free[n]) for n in free}
               for g in response_guesses(series, like, bounds)]
    best = max(guesses, key=lambda g: _finite(problem.log_posterior(problem.space.to_z(g))))
    for line in lines:  # seen only at second order, the phase is defined modulo pi
        c, half = best[line.phase], 0.5 * like.phase_period(line.phase)
        free[line.phase] = Prior("uniform", (c - half, c + half))
    return free


def free_defaults(table: dict, series: Series, like=None) -> dict[str, Prior]:
    """The default free parameters of the scene's kind (frame or deterministic)."""
    from vibinverse.frame_model import frame_surface, is_frame

    if is_frame(table):
        return default_free(f"surfaces.{frame_surface(table)}.motion.", table, series)
    return response_free(table, series, like)


def run_fit(problem: Problem, method: str, *, seed: int = 0, backend: Path | None = None, resume: bool = False,
            workers: int = 1, max_steps: int = 20000, progress: bool = True) -> tuple[dict, dict]:
    """Fit; returns (summary, extras for the netCDF: chains, log_prob, predictive)."""
    if method not in METHODS:
        raise SceneError(f"--method: {method!r} is not one of {', '.join(METHODS)}")
    names = problem.space.names
    nyq = 0.5 * problem.series.fs
    for n, p in zip(names, problem.space.priors):
        if n.split("[")[0].endswith("frequency"):
            lo, hi = p.bounds
            if hi > nyq * (1 + 1e-12):
                raise SceneError(f"{n}: the prior reaches {hi:g} Hz, above the Nyquist frequency {nyq:g} Hz of the data")
            check_resolves(problem.series, max(lo, 1e-12), n)  # the lowest frequency needs the longest record
    timing: dict[str, float] = {}
    t0 = time.perf_counter()
    bounds = {n: p.bounds for n, p in zip(names, problem.space.priors)}
    if method == "sindy" and problem.kind != "frame":
        raise SceneError("--method sindy: SINDy identifies a noise-driven resonance (a frame scene); this scene's "
                         "motion is deterministic: use spectral, map, mcmc or auto")
    starts = [{n: _inside(g.get(n, _prior_centre(p)), p) for n, p in zip(names, problem.space.priors)}
              for g in _guesses(problem, bounds)]
    # which periodogram line is the drive: the candidates' exact posterior decides (best first)
    starts.sort(key=lambda st: -_finite(problem.log_posterior(problem.space.to_z(st))))
    start = starts[0]
    timing["spectral_s"] = time.perf_counter() - t0
    truth = problem.truth()
    data = {"source": problem.series.source, "description": problem.series.describe(),
            "n_gaps": problem.series.n_gaps, "n_samples": int(problem.series.time.size)}
    if problem.kind == "response":  # which reduced model is the likelihood's mean, and its error bound
        data["model"] = {"kind": problem.like.model, "error_bound": problem.like.model_error}
    if method == "spectral":
        return summarize("spectral", names, start, None, None, truth, {"converged": None, **detection(problem, start)},
                         timing, data, problem.space.priors), _predictive(problem, start, None)
    if method == "sindy" or (method == "auto" and problem.kind == "frame"):
        t0 = time.perf_counter()
        sindy = _sindy(problem, starts)
        timing["sindy_s"] = time.perf_counter() - t0
        if method == "sindy":
            values = sindy.pop("_values", start)
            sd = sindy.pop("_sd", None)
            diag = {"converged": None, "sindy": sindy, **detection(problem, values)}
            return (summarize("sindy" if sd is not None else "spectral", names, values, None, sd, truth, diag, timing,
                              data, problem.space.priors), _predictive(problem, values, None))
        if "_values" in sindy:  # SINDy seeds the MAP
            starts = [sindy.pop("_values"), *starts]
            sindy.pop("_sd", None)
    t0 = time.perf_counter()
    fit, map_method = _map(problem, starts, method, seed)
    if problem.kind == "response" and _taylor_too_coarse(problem, fit["values"], data):
        print("the Taylor model's error is not small against the noise at the fit; refitting with the "
              "compiled (Chebyshev) model", flush=True)
        problem.like.use_compiled()
        data["model"]["kind"] = problem.like.model
        fit, map_method = _map(problem, [fit["values"]], method, seed)
    timing[f"{map_method}_s"] = time.perf_counter() - t0
    if method in ("map", "casadi"):
        draws = _laplace_draws(problem, fit, seed)
        diag = {"converged": bool(np.isfinite(fit["log_post"])), "log_posterior": fit["log_post"],
                "hessian_positive_definite": fit.get("hessian_ok", True), **detection(problem, fit["values"])}
        extras = _predictive(problem, fit["values"], draws)
        extras["_draws"] = draws[None, ...]
        return summarize(map_method, names, fit["values"], None, fit["sd"], truth, diag, timing, data,
                         problem.space.priors), extras
    t0 = time.perf_counter()
    backend = backend or Path("vibinverse-chain.h5")
    print(f"sampling with emcee (checkpoint {backend}) ...", flush=True)
    res = mcmc.run(problem, fit["z"], fit["cov_z"], backend, resume=resume, workers=workers, seed=seed,
                   max_steps=max_steps, progress=progress)
    timing["mcmc_s"] = time.perf_counter() - t0
    chain = res["chain"]
    burn = int(min(chain.shape[0] // 2, 3 * np.nanmax(res["tau"]) if np.all(np.isfinite(res["tau"])) else chain.shape[0] // 2))
    kept = chain[burn:]
    values = np.array([[list(problem.values(z).values()) for z in walker] for walker in kept.transpose(1, 0, 2)])
    diag = {**_diagnostics(values, res), "multimodal": multimodal(values, names), **detection(problem, fit["values"])}
    if method == "auto" and problem.kind == "frame":
        diag["sindy"] = sindy
    flat = values.reshape(-1, values.shape[-1])
    summary = summarize("mcmc" if method == "mcmc" else "auto", names, fit["values"], flat, None, truth, diag, timing,
                        data, problem.space.priors)
    extras = _predictive(problem, fit["values"], flat)
    extras["_chains"] = values
    extras["_log_prob"] = res["log_prob"][burn:].T
    return summary, extras


def _taylor_too_coarse(problem: Problem, values: dict[str, float], data: dict) -> bool:
    """Whether the Taylor mean's error bound at the fit exceeds TAYLOR_TOLERANCE x the noise sd
    (the model was chosen at the scene's values; the fit may sit at a larger amplitude)."""
    from vibinverse.response_model import TAYLOR_TOLERANCE

    like = problem.like
    if like.model != "taylor2":
        return False
    bound = like.taylor_error(values)
    data["model"]["error_bound_at_fit"] = bound
    sd = float(np.sqrt(np.mean(like.variance(like.mean(values), values))))
    return bound > TAYLOR_TOLERANCE * sd


def _guesses(problem: Problem, bounds: dict[str, tuple[float, float]]) -> list[dict[str, float]]:
    if problem.kind == "frame":
        return frame_guesses(problem.series, problem.like, bounds)
    from vibinverse.estimators.response_spectral import response_guesses

    return response_guesses(problem.series, problem.like, bounds)


def _sindy(problem: Problem, starts: list[dict]) -> dict:
    """SINDy from the spectral candidates: {"status": "ok", "equation", "misfit", "_values", "_sd"}
    restricted to the free parameters, or {"status": "declined", "reason"}."""
    from vibinverse.estimators.sindy import SindyFailed, sindy_best

    names = problem.space.names
    try:
        res = sindy_best(problem.series, problem.like, [{**_fixed_values(problem), **s} for s in starts])
    except SindyFailed as exc:
        print(f"{exc}; continuing without it", flush=True)
        return {"status": "declined", "reason": str(exc)}
    bounds = {n: p for n, p in zip(names, problem.space.priors)}
    values = {n: _inside(res["values"].get(n, s), bounds[n]) for n, s in starts[0].items() if n in bounds}
    sd = {n: v for n, v in res["sd"].items() if n in values}
    print(f"sindy: {res['equation']}", flush=True)
    return {"status": "ok", "equation": res["equation"], "misfit": res["misfit"], "_values": values, "_sd": sd}


def _fixed_values(problem: Problem) -> dict[str, float]:
    """Scene values of the frame parameters that are not free (SINDy reads the whole set)."""
    out = {}
    k = problem.like.key
    for n in (k + "tilt_frequency", k + "tilt_damping_ratio", k + "noise_rms", "noise.sigma"):
        try:
            out[n] = problem.like._base_value(n)
        except SceneError:
            pass
    if problem.like.base["surfaces"][problem.like.roof]["motion"].get("drive_frequency"):
        out[k + "drive_frequency"] = problem.like._line({}, "drive_frequency", 0)
    return out


def _map(problem: Problem, starts: list[dict], method: str, seed: int) -> tuple[dict, str]:
    """MAP from every candidate start (each candidate line as the drive; the posterior decides).
    casadi + IPOPT with exact derivatives, except for method "map" (derivative-free scipy), which is
    also the fallback should IPOPT fail."""
    if method != "map" and problem.kind == "frame" and problem.like.geometry_free(problem.space.names):
        print(f"the casadi MAP holds the observation fixed; {', '.join(problem.like.geometry_free(problem.space.names))} "
              "re-form it, so the scipy MAP is used", flush=True)
    elif method != "map":
        try:
            from vibinverse.estimators.casadi_map import casadi_map
            from vibinverse.estimators.casadi_response import Unsupported

            return casadi_map(problem, starts), "casadi"
        except Unsupported as exc:
            print(f"the casadi MAP does not cover this fit ({exc}); using the scipy MAP", flush=True)
        except Exception as exc:  # noqa: BLE001 - any solver failure falls back, and says so
            print(f"casadi MAP failed ({str(exc).splitlines()[0][:120]}); using the derivative-free MAP", flush=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        fits = [map_fit.map_fit(problem, st, restarts=1, seed=seed) for st in starts]
    return max(fits, key=lambda f: f["log_post"]), "map"


def detection(problem: Problem, values: dict[str, float]) -> dict:
    """Whether the data show each fitted line (`_frame_detection`, `_response_detection`)."""
    if problem.kind == "frame":
        return _frame_detection(problem, values)
    return _response_detection(problem, values)


def _threshold(problem: Problem, frequency: str | None) -> float:
    """12.5, plus ln(independent frequencies in the prior) when the frequency is free."""
    span = float(problem.series.time[-1] - problem.series.time[0] + problem.series.dt)
    bounds = dict(zip(problem.space.names, (p.bounds for p in problem.space.priors)))
    lo, hi = bounds.get(frequency, (0.0, 0.0))
    return DETECTION_GAIN + math.log(max(1.0, (hi - lo) * span))


def _response_detection(problem: Problem, values: dict[str, float]) -> dict:
    """Each line's log-likelihood gain over the same fit with its amplitude set to 0, against the
    threshold of `_frame_detection`. Keys vibration_* (one line) or vibration_i_* (several)."""
    from vibinverse.estimators.response_spectral import free_name

    like = problem.like
    ll = like.log_likelihood(values)
    lines = like.lines()
    out = {}
    for i, line in enumerate(lines):
        what = "vibration" if len(lines) == 1 else f"vibration_{i}"
        zero = {**values, line.amplitude: 0.0}
        if free_name(line.amplitude, set(values)) and line.amplitude not in values:
            zero[line.amplitude[:-3]] = 0.0
        threshold = _threshold(problem, free_name(line.frequency, set(problem.space.names)))
        gain = ll - like.log_likelihood(zero)
        out.update({f"{what}_delta_loglike": float(gain), f"{what}_threshold": threshold,
                    f"{what}_detected": bool(gain > threshold)})
    return out


def _frame_detection(problem: Problem, values: dict[str, float]) -> dict:
    """Log-likelihood gain of the fitted drive line and tilt resonance over the same fit without
    them, against a threshold of 12.5 (5 sigma for one added line at a known frequency) plus
    ln(N), N the number of independent frequencies (prior width x record span) the fit could have
    put the line at: the look-elsewhere effect of a free frequency (Bonferroni over Fourier bins).
    Below it the data do not show the line: say so, do not report it."""
    key = problem.like.key
    ll = problem.like.log_likelihood(values)
    out = {}
    for what, name, freq in (("drive", "drive_amplitude", "drive_frequency"), ("resonance", "noise_rms", "tilt_frequency")):
        if key + name in values:
            ll0 = problem.like.log_likelihood({**values, key + name: 0.0})
            threshold = _threshold(problem, key + freq)
            out[f"{what}_delta_loglike"] = float(ll - ll0)
            out[f"{what}_threshold"] = threshold
            out[f"{what}_detected"] = bool(ll - ll0 > threshold)
    return out


def detections(diagnostics: dict) -> list[tuple[str, float, float, bool]]:
    """(what, log-likelihood gain, threshold, detected) of every line tested in `diagnostics`."""
    out = []
    for key, detected in diagnostics.items():
        if key.endswith("_detected"):
            what = key[:-len("_detected")]
            out.append((what.replace("_", " "), diagnostics[f"{what}_delta_loglike"],
                        diagnostics.get(f"{what}_threshold", DETECTION_GAIN), bool(detected)))
    return out


def multimodal(values: np.ndarray, names: list[str], separation: float = 5.0) -> list[str]:
    """Parameters whose walkers sit in separate groups: sorted walker means with a gap wider than
    `separation` times the typical within-walker sd, and at least 2 walkers on each side. An
    ensemble sampler's walkers do not cross between well-separated modes, so this is how a second
    mode shows. values: (walker, draw, parameter)."""
    out = []
    for j, n in enumerate(names):
        means = np.sort(values[:, :, j].mean(axis=1))
        within = float(np.median(values[:, :, j].std(axis=1)))
        gaps = np.diff(means)
        k = int(np.argmax(gaps)) if gaps.size else -1
        if k >= 1 and k <= len(means) - 3 and gaps[k] > separation * max(within, 1e-300):
            out.append(n)
    return out


def _diagnostics(values: np.ndarray, res: dict) -> dict:
    """Split R-hat and bulk ESS from ArviZ over walkers (chain = walker), emcee's tau."""
    import arviz as az

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = az.convert_to_dataset({f"p{j}": values[..., j] for j in range(values.shape[-1])})
        rhat = float(np.nanmax([az.rhat(ds)[v].item() for v in ds.data_vars]))
        ess = float(np.nanmin([az.ess(ds)[v].item() for v in ds.data_vars]))
    return {"rhat_max": rhat, "ess_min": ess, "tau_max": float(np.nanmax(res["tau"])), "n_steps": int(res["n_steps"]),
            "nwalkers": int(res["nwalkers"]), "acceptance": res["acceptance"],
            "converged": bool(res["converged"] and rhat < 1.05)}


def _laplace_draws(problem: Problem, fit: dict, seed: int, n: int = 2000) -> np.ndarray:
    rng = np.random.default_rng(seed)
    z = rng.multivariate_normal(fit["z"], fit["cov_z"], size=n, method="eigh")
    return np.array([list(problem.values(zi).values()) for zi in z])


def _predictive(problem: Problem, values: dict[str, float], draws: np.ndarray | None) -> dict[str, np.ndarray]:
    """The model mean at the point estimate and its 5-95 % band over up to 100 draws."""
    mean = problem.like.mean(values)
    out = {"model_mean": mean}
    if draws is not None and len(draws):
        rng = np.random.default_rng(0)
        pick = draws[rng.choice(len(draws), size=min(100, len(draws)), replace=False)]
        curves = np.array([problem.like.mean(dict(zip(problem.space.names, d))) for d in pick])
        out["model_q05"], out["model_q95"] = np.percentile(curves, [5, 95], axis=0)
    return out


def _finite(v: float) -> float:
    return v if np.isfinite(v) else -np.inf


def _prior_centre(p: Prior) -> float:
    lo, hi = p.bounds
    if p.kind == "loguniform":
        return float(np.sqrt(lo * hi))
    if np.isfinite(lo) and np.isfinite(hi):
        return 0.5 * (lo + hi)
    return p.args[0]


def _inside(v: float, p: Prior) -> float:
    lo, hi = p.bounds
    span = hi - lo if np.isfinite(hi - lo) else 1.0
    return float(np.clip(v, lo + 1e-6 * span, hi - 1e-6 * span)) if np.isfinite(v) else _prior_centre(p)

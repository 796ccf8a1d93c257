"""The robustness bench's oracle (`vibinverse.bench.robustness_bench`).

What the data can decide (`oracle`): for each true mode and line of a data set, its gain in
log-likelihood at the TRUE parameters of everything (the simulator's: level, the other components,
the noise, the data set's own drift and gain drift), ln L with it - ln L without it, from the exact
Gaussian likelihood (the modal model's Kalman filter where it is the case's exact model, else the
dense covariance of the observed samples, `ORACLE_LIKELIHOODS`), against the threshold the order
search asks of a mode or line (1.5 ln n + ln M: BIC's three parameters and the look-elsewhere term;
a line also the detection test's 12.5 + ln N) and against it without the look-elsewhere term (a
user who knows the frequency), and refitted: both orders fitted by maximum likelihood from the
truth, the statistic the order search compares at its best. The fractions passing
(`oracle_detection`, `oracle_known_frequency`, `oracle_refit_detection` in the rows) approximately
bound what any search with that threshold can find (approximately: the search compares maxima,
which differ from the truth's both ways, `oracle`). The case near_drive raises weak_drive's line until the
oracle decides it in >= 97 % of the records, also with the other components refitted: there, a
miss is the search's.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import replace
from typing import Any, ClassVar

import numpy as np

from vibinverse.bench.robustness_cases import (
    CASES,
    AR1Noise,
    Case,
    FlickerNoise,
    Mode,
    WhiteNoise,
    intensity,
    simulate_parts,
)
from vibinverse.detection import DETECTION_GAIN


def mode_covariance(mode: Mode, lag: np.ndarray) -> np.ndarray:
    """The oscillator's stationary autocovariance at time lags (s), underdamped (zeta < 1):
    rms^2 e^(-zeta w |lag|) [cos(w_d lag) + zeta / sqrt(1 - zeta^2) sin(w_d |lag|)], w_d = w sqrt(1 - zeta^2)."""
    z = mode.damping_ratio
    if not 0.0 < z < 1.0:
        raise ValueError(f"damping_ratio: {z}; allowed: (0, 1) (an underdamped oscillator)")
    w = 2.0 * math.pi * mode.frequency
    wd, a = w * math.sqrt(1.0 - z * z), np.abs(lag)
    return mode.rms**2 * np.exp(-z * w * a) * (np.cos(wd * a) + z / math.sqrt(1.0 - z * z) * np.sin(wd * a))


class OracleNoise(ABC):
    """How the oracle treats a kind of the simulator's sensor noise (`Case.noise`, `ORACLE_NOISES`):
    its autocovariance, how the modal model describes it, and whether that model's Kalman filter
    is its exact likelihood."""

    #: the modal model's `noise` for it ("white": the model's white noise alone)
    modal_noise: ClassVar[str]

    @abstractmethod
    def covariance(self, case: Case, lag: np.ndarray, steps: np.ndarray) -> np.ndarray:
        """The autocovariance at time lags (s) and lags in samples (`steps`)."""

    def modal_values(self, case: Case) -> dict[str, float]:
        """The modal model's noise parameters at the truth, `noise.sigma` first (0: no white noise)."""
        return {"noise.sigma": 0.0}

    def kalman_exact(self, t: np.ndarray) -> bool:
        """Whether the modal model's Kalman filter is the noise's exact likelihood on the stamps `t`."""
        return False


class WhiteOracle(OracleNoise):
    """Independent samples: the modal model's white noise."""

    modal_noise = "white"

    def covariance(self, case: Case, lag: np.ndarray, steps: np.ndarray) -> np.ndarray:
        return np.where(steps == 0, case.sigma**2, 0.0)

    def modal_values(self, case: Case) -> dict[str, float]:
        return {"noise.sigma": case.sigma}

    def kalman_exact(self, t: np.ndarray) -> bool:
        return True


class AR1Oracle(OracleNoise):
    """The simulator's AR(1) runs per sample (`ar1`): an Ornstein-Uhlenbeck process, the modal
    model's AR(1) noise, only when the samples are evenly spaced."""

    modal_noise = "ar1"

    def covariance(self, case: Case, lag: np.ndarray, steps: np.ndarray) -> np.ndarray:
        # phi to the power of the lag in samples
        return case.sigma**2 * case.ar_phi ** np.abs(steps).astype(float)

    def modal_values(self, case: Case) -> dict[str, float]:
        return {"noise.sigma": 0.0, "ar.rms": case.sigma, "ar.time": -1.0 / (case.fs * math.log(case.ar_phi))}

    def kalman_exact(self, t: np.ndarray) -> bool:
        from vibinverse.io.series import evenly_spaced

        return evenly_spaced(t)


class FlickerOracle(OracleNoise):
    """A sum of Ornstein-Uhlenbeck processes: the modal model reads it as white noise (the dense
    likelihood only)."""

    modal_noise = "white"

    def covariance(self, case: Case, lag: np.ndarray, steps: np.ndarray) -> np.ndarray:
        var = case.sigma**2 / len(case.flicker_times)
        return sum(var * np.exp(-np.abs(lag) / tau) for tau in case.flicker_times)


#: the oracle's view of each kind of sensor noise, by the case's name of it
ORACLE_NOISES: dict[str, OracleNoise] = {
    WhiteNoise.name: WhiteOracle(),
    AR1Noise.name: AR1Oracle(),
    FlickerNoise.name: FlickerOracle(),
}


def _lag_matrix(t: np.ndarray, kernel: Callable[[np.ndarray, np.ndarray], np.ndarray], keep: np.ndarray) -> np.ndarray:
    """kernel(t_i - t_j, i - j) over the samples `keep` (a mask of t): on evenly spaced stamps from
    its first column (a Toeplitz matrix), else pairwise."""
    from scipy.linalg import toeplitz

    from vibinverse.io.series import evenly_spaced

    n = t.size
    if evenly_spaced(t):
        full = toeplitz(kernel(t - t[0], np.arange(n)))
        return full[np.ix_(keep, keep)]
    idx = np.flatnonzero(keep)
    return kernel(t[idx][:, None] - t[idx][None, :], idx[:, None] - idx[None, :])


def _oracle_values(case: Case, truth: dict) -> dict[str, float]:
    """The modal model's parameters at the truth (its modes and lines sorted by frequency)."""
    noise = ORACLE_NOISES[case.noise].modal_values(case)
    v = {"level": case.level, "noise.sigma": noise.pop("noise.sigma")}
    for i, m in enumerate(truth["modes"]):
        v.update({f"modes[{i}].{k}": m[k] for k in ("frequency", "damping_ratio", "rms")})
    for j, ln in enumerate(truth["lines"]):
        v.update({f"lines[{j}].{k}": ln[k] for k in ("frequency", "amplitude", "phase")})
    v.update(noise)
    return v


def kalman_exact(case: Case, t: np.ndarray) -> bool:
    """Whether the modal model's Kalman filter is the case's exact likelihood once the known drift
    is subtracted: no gain drift, and white noise, or AR(1) noise on uniform stamps (the simulator's
    AR(1) runs per sample, an Ornstein-Uhlenbeck process only when the samples are evenly spaced)."""
    return not case.gain and ORACLE_NOISES[case.noise].kalman_exact(t)


def _kalman_gains(case: Case, t: np.ndarray, parts: dict, truth: dict, model) -> dict[tuple[str, int], float]:
    """ln L(truth) - ln L(truth without the component) of each mode (rms 0) and line (amplitude 0),
    by the modal model's Kalman filter on the data minus the known drift."""
    v = _oracle_values(case, truth)
    ll = model.log_likelihood(v)
    out = {}
    for kind, key, count in (("modes", "rms", len(case.modes)), ("lines", "amplitude", len(case.lines))):
        for i in range(count):
            out[kind, i] = ll - model.log_likelihood({**v, f"{kind}[{i}].{key}": 0.0})
    return out


def _gaussian_log_likelihood(r: np.ndarray, cov: np.ndarray) -> float:
    from scipy.linalg import cho_factor, cho_solve

    c = cho_factor(cov, lower=True, check_finite=False)
    return float(-0.5 * (r @ cho_solve(c, r) + 2.0 * np.log(np.diag(c[0])).sum() + r.size * math.log(2 * math.pi)))


def _dense_gains(case: Case, t: np.ndarray, parts: dict, truth: dict, model) -> dict[tuple[str, int], float]:
    """The same log-likelihood ratios from the dense covariance of the observed samples (O(n^3);
    any case): y - drift = (1 + g) (level + lines + modes) + noise, g and the drift the data set's
    own (known), the modes' covariance scaled by (1 + g_i)(1 + g_j)."""
    good = ~parts["gaps"]
    tt = t[good]
    y = (parts["y"] - parts["drift"])[good]
    s = 1.0 + parts["gain"][good]
    scale = np.outer(s, s)
    modes = [scale * _lag_matrix(t, lambda lag, _, m=Mode(**m): mode_covariance(m, lag), good) for m in truth["modes"]]  # noqa: B008 - Mode is frozen
    noise = _lag_matrix(t, lambda lag, steps: ORACLE_NOISES[case.noise].covariance(case, lag, steps), good)
    lines = [ln["amplitude"] * np.cos(2 * np.pi * ln["frequency"] * tt + ln["phase"]) for ln in truth["lines"]]
    r = y - s * (case.level + sum(lines, np.zeros(tt.size)))
    cov = noise + sum(modes, np.zeros_like(noise))
    ll = _gaussian_log_likelihood(r, cov)
    out = {}
    for i, k in enumerate(modes):
        out["modes", i] = ll - _gaussian_log_likelihood(r, cov - k)
    for j, line in enumerate(lines):
        out["lines", j] = ll - _gaussian_log_likelihood(r + s * line, cov)
    return out


#: how the oracle's log-likelihoods are computed: the modal model's Kalman filter (exact for the
#: cases `kalman_exact` names, O(n)) or the dense Gaussian of the observed samples (any case, O(n^3))
ORACLE_LIKELIHOODS: dict[str, Callable[..., dict[tuple[str, int], float]]] = {
    "kalman": _kalman_gains,
    "dense": _dense_gains,
}


def _refit_gains(case: Case, t: np.ndarray, parts: dict, truth: dict, model) -> dict[tuple[str, int], float]:
    """max ln L with each component - max ln L without it, both orders fitted by maximum likelihood
    (`vibinverse.model_order.fit_order`, the order search's) from the truth, on the data minus the
    known drift: the statistic the order search compares, its other components refitted."""
    from vibinverse.model_order import fit_order, renumber

    values = _oracle_values(case, truth)
    spec = model.spec
    full = fit_order(model.series, spec, [values]).log_likelihood
    out = {}
    for kind, count in (("modes", spec.modes), ("lines", spec.lines)):
        fewer = replace(spec, **{kind: count - 1})
        for i in range(count):
            out[kind, i] = full - fit_order(model.series, fewer, [renumber(values, kind, i, count)]).log_likelihood
    return out


def oracle_thresholds(model, kind: str) -> tuple[float, float]:
    """(threshold, threshold at a known frequency) of the log-likelihood gain a mode or a line
    must show in the modal model `model` (built on the data): the order search's BIC term for 3
    parameters, 1.5 ln n, plus its look-elsewhere term ln M (`vibinverse.model_order`); a line must
    also pass the detection test, 12.5 + ln N (`vibinverse.detection`), so its threshold is the
    larger of the two. At a known frequency the look-elsewhere terms ln M, ln N are left out."""
    n = model.n_obs
    bic = 1.5 * math.log(n)
    searched = bic + math.log(model.frequencies_searched)
    if kind == "modes":
        return searched, bic
    series = model.series
    lo, hi = model.default_priors()["lines[0].frequency"].bounds
    span = float(series.time[-1] - series.time[0] + series.dt)  # as `vibinverse.detection.threshold`
    detection = DETECTION_GAIN + math.log(max(1.0, (hi - lo) * span))
    return max(searched, detection), max(bic, DETECTION_GAIN)


def oracle(
    case: Case | str, seed: int, quick: bool = False, likelihood: str | None = None, refit: bool = False
) -> list[dict[str, Any]]:
    """What the data set can decide: for each true mode and line of `simulate(case, seed, quick)`,
    the log-likelihood gain `gain` = ln L(everything at the truth) - ln L(the same without that
    component: a mode's rms, a line's amplitude to 0), the simulator's true parameters for all the
    rest (level, the other components, the noise; the data set's own drift and gain drift as
    known), its `threshold` and `threshold_known` (`oracle_thresholds`) and whether it passes
    them (`detected`, `detected_known`). `likelihood`: "kalman" or "dense" (`ORACLE_LIKELIHOODS`;
    default: the Kalman filter where `kalman_exact`, else dense). The fraction of data sets passing
    is an approximate upper bound on what a search with that threshold finds (with
    `threshold_known`, what a user who knows the frequency could), approximate because the search
    compares maxima, not the truth: refitted, the gain grows by ~ half the added parameters but
    shrinks where the other components' fitted values absorb part of the component (a line next to
    a resonance). `refit` (the Kalman-exact cases; None elsewhere) adds `gain_refit` and
    `detected_refit`: both orders fitted by maximum likelihood from the truth (`_refit_gains`), the
    order search's own statistic at its best (0.3-1 s a data set). Seeds 0-49, passing at the truth
    / refitted: weak_drive's line 21 / 10 of 50, ar1's mode 28 / 27, near_drive's line 50 / 50."""
    import vibinverse as vi
    from vibinverse.models.modal import ModalModel

    case = CASES[case] if isinstance(case, str) else case
    t, parts, truth = simulate_parts(case, seed, quick)
    parts["y"] = intensity(case, parts)
    if not case.modes and not case.lines:
        return []
    series = vi.series(t, parts["y"] - parts["drift"], source="robustness oracle")
    spec = {"modes": len(case.modes), "lines": len(case.lines), "noise": ORACLE_NOISES[case.noise].modal_noise}
    model = ModalModel({"modal": spec}, series)
    how = likelihood or ("kalman" if kalman_exact(case, t) else "dense")
    if how not in ORACLE_LIKELIHOODS:
        raise ValueError(f"likelihood: {how!r}; allowed: {', '.join(ORACLE_LIKELIHOODS)}")
    if how == "kalman" and not kalman_exact(case, t):
        raise ValueError(f"likelihood: 'kalman' is not exact for the case {case.name!r}; allowed: 'dense'")
    for kind in ("modes", "lines"):  # the modal model's labelling: by increasing frequency
        truth[kind] = sorted(truth[kind], key=lambda c: c["frequency"])
    gains = ORACLE_LIKELIHOODS[how](case, t, parts, truth, model)
    refits = _refit_gains(case, t, parts, truth, model) if refit and kalman_exact(case, t) else {}
    out = []
    for kind in ("modes", "lines"):
        if not truth[kind]:
            continue
        limit, known = oracle_thresholds(model, kind)
        for i, comp in enumerate(truth[kind]):
            g = float(gains[kind, i])
            out.append(
                {
                    "kind": kind,
                    "frequency": comp["frequency"],
                    "gain": g,
                    "threshold": limit,
                    "threshold_known": known,
                    "detected": bool(g > limit),
                    "detected_known": bool(g > known),
                    "likelihood": how,
                }
            )
            if refit:
                r = refits.get((kind, i))
                out[-1].update({"gain_refit": r, "detected_refit": None if r is None else bool(r > limit)})
    return out

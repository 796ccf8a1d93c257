"""The answer first: which lines the data show, where, how surely, and whether the fit can be trusted.

`verdict(summary)` reads a result's JSON summary (`FitResult.summary()`, `read_result(path)[0]`)
and returns a `Verdict`: one `VerdictLine` per line tested (the detection test's
`{what}_detected`, `{what}_delta_loglike`, `{what}_threshold` and
`{what}_false_alarm_probability` diagnostics, `vibinverse.detection`) with its frequency +- its
uncertainty, and a trust decision from the sampler's convergence (R-hat, ESS, `converged`) and the
residual checks (`diagnostics["residual_checks"]`, `vibinverse.checks`). `Verdict.headline` is one
plain-text line the command line prints; the HTML report's first box shows the same. A line the
scene sees only at second order (the summary's `data.model.second_order`, e.g. a plate over a
symmetric footprint) is reported at its own frequency f, with a note that the data's line is at 2f.

Trust is decided, not guessed: `trusted` is False when any check fails (not converged, R-hat above
1.01 or ESS below 400, residuals not white or not Gaussian, a Hessian that is not positive definite,
modes the data cannot tell apart), True when every check that applies passed, and None when one
was not made (residuals not checked, no R-hat). A crafted or foreign summary (strings where numbers
belong) never raises: a value that is not a number reads as unknown.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from vibinverse.stationarity import describe_change

RHAT_MAX = 1.01  # rank-normalized split R-hat (Vehtari et al. 2021), the sampler's own stopping rule
ESS_MIN = 400.0  # bulk and tail ESS

#: how the summary's `approximation` reads in a sentence
APPROXIMATIONS = {
    "laplace": "Laplace approximation",
    "jackknife": "jackknife approximation",
    "spectral": "spectral approximation",
    "importance": "Laplace approximation corrected by importance sampling (PSIS)",
}

#: how a line test's label reads
_LABELS = {"drive": "drive line", "resonance": "tilt resonance", "vibration": "vibration", "decay": "free decay"}


def as_number(v: Any) -> float:
    """`v` as a float; NaN for null (a non-finite number in strict JSON) or anything not a number."""
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else math.nan


def format_number(v: Any, spec: str) -> str:
    """A number formatted by `spec`; "n/a" for NaN, null or anything not a number."""
    x = as_number(v)
    return "n/a" if math.isnan(x) else format(x, spec)


def format_probability(p: Any) -> str:
    """A probability for a reader: 0.23, 0.012, 3.1e-07; "< 1e-300" when it underflows to 0."""
    x = as_number(p)
    if math.isnan(x):
        return "n/a"
    if x <= 0.0:
        return "< 1e-300"
    return format(x, ".2g") if x >= 0.01 else format(x, ".1e")


def format_value(value: Any, uncertainty: Any, plus_minus: str = "+-") -> str:
    """value +- uncertainty, the uncertainty to 1 significant digit (2 when it starts with a 1) and
    the value to the same decimal place: 3.466 +- 0.004, 10.0000 +- 0.0001."""
    v, u = as_number(value), as_number(uncertainty)
    if math.isnan(v):
        return "n/a"
    if not math.isfinite(u) or u <= 0.0:
        return f"{v:.8g} {plus_minus} n/a"
    exponent = math.floor(math.log10(u))
    if u / 10.0**exponent < 1.95:  # a leading 1: two digits
        exponent -= 1
    decimals = min(max(-exponent, 0), 15)
    if decimals == 0 and abs(v) >= 1e7:
        return f"{v:.6g} {plus_minus} {u:.2g}"
    return f"{v:.{decimals}f} {plus_minus} {u:.{decimals}f}"


def approximation(summary: dict) -> str | None:
    """What the intervals are when they are not quantiles of real posterior draws (None when they
    are): the summary's `approximation`; for an older summary without it, its method's
    (`FitMethod.approximation`), "laplace" for a method that is not one of them."""
    if "approximation" in summary:
        a = summary.get("approximation")
        return None if a is None else str(a)
    from vibinverse.pipeline import FIT_METHODS  # only for an older summary: the fitting stack is heavy

    method = FIT_METHODS.get(str(summary.get("method", "")))
    return "laplace" if method is None else method.approximation


def approximation_label(kind: str | None) -> str:
    """ "Laplace approximation", ...; "" for real posterior draws."""
    if kind is None:
        return ""
    return APPROXIMATIONS.get(kind, f"{kind} approximation")


@dataclass
class VerdictLine:
    """One line tested: is it detected, where, and how likely is a gain this large from noise alone."""

    what: str  # the diagnostics key's stem: "drive", "resonance", "vibration_0"
    label: str  # how it reads: "drive line", "tilt resonance", "vibration 0"
    detected: bool
    delta_loglike: float
    threshold: float
    false_alarm_probability: float  # NaN when the result does not carry it
    parameter: str | None = None  # the frequency's parameter name, None when it is not fitted
    value: float = math.nan
    uncertainty: float = math.nan
    uncertainty_kind: str = ""  # "sd" or "half the 90 % interval"
    units: str = "Hz"
    second_order: bool = False  # the scene sees the line only at second order: the data show it at 2f
    broad: bool = False  # a resonance too damped to be one (`vibinverse.detection.BROAD_DAMPING`)
    product: str = ""  # the stronger tones it is a product of (`vibinverse.detection.products`)
    harmonic: str = ""  # k x f of a stronger tone: claimed, and named

    def where(self, plus_minus: str = "+-") -> str:
        """ "at 3.466 +- 0.004 Hz", or "" when the frequency is not fitted."""
        if self.parameter is None or math.isnan(self.value):
            return ""
        return f"at {format_value(self.value, self.uncertainty, plus_minus)} {self.units}".rstrip()

    def _named(self, what: str, plus_minus: str) -> str:
        """ "mode 2 at 4.47 +- 0.08 Hz: `what`" ("mode 2: `what`" when the frequency is not fitted)."""
        where = self.where(plus_minus)
        return f"{self.label} {where}: {what}" if where else f"{self.label}: {what}"

    def text(self, plus_minus: str = "+-") -> str:
        """ "tilt resonance detected at 3.466 +- 0.004 Hz", "drive line not detected (false-alarm
        probability 0.68)"; a line seen only at second order says that its spectral line is at 2f
        (the fit reports f, the frequency of the motion); a broad hump says so ("mode 2 at 4.47 +-
        0.08 Hz: a broad hump, not claimed as a resonance"), and a product of stronger tones ("line 3
        at 319.9998 +- 0.0002 Hz: 120 + 2 x 100.001 Hz, a product of stronger tones, not claimed")."""
        if self.product:
            return self._named(f"{self.product}, a product of stronger tones, not claimed", plus_minus)
        if self.broad:
            return self._named("a broad hump, not claimed as a resonance", plus_minus)
        if self.detected:
            where = self.where(plus_minus)
            text = f"{self.label} detected {where}".rstrip() if where else f"{self.label} detected"
            if self.second_order and where:
                twice = format_number(2 * self.value, ".6g")
                text += f" (seen at second order: the data's line is at {twice} {self.units})"
            if self.harmonic:
                text += f" ({self.harmonic}: a harmonic of a stronger tone, or a mode of its own)"
            return text
        return f"{self.label} not detected (false-alarm probability {format_probability(self.false_alarm_probability)})"


@dataclass
class Verdict:
    """The lines, whether the fit can be trusted (None: not decided), why, and one line to print."""

    lines: list[VerdictLine]
    trusted: bool | None
    reasons: list[str] = field(default_factory=list)
    headline: str = ""
    trust_summary: str = ""  # "fit trustworthy (R-hat 1.008, residuals white)"


def _frequency_parameter(what: str, parameters: dict[str, Any]) -> str | None:
    """The parameter holding the frequency of line test `what`: the drive's drive_frequency (its
    i-th for `drive_i`), the resonance's tilt_frequency, the i-th other frequency for `vibration_i`."""
    freqs = [n for n in parameters if str(n).split(".")[-1].split("[")[0].endswith("frequency")]
    m = re.fullmatch(r"(.*?)(?:_(\d+))?", what)
    stem, index = (m.group(1), m.group(2)) if m else (what, None)
    i = int(index) if index is not None else 0
    if stem == "drive":
        pool = [n for n in freqs if "drive_frequency" in n]
    elif stem == "resonance":
        pool = [n for n in freqs if "tilt_frequency" in n]
    else:
        pool = [n for n in freqs if "drive_frequency" not in n and "tilt_frequency" not in n]
    if index is None and len(pool) == 1:
        return pool[0]
    indexed = [n for n in pool if n.endswith(f"[{i}]")]
    if len(indexed) == 1:
        return indexed[0]
    return pool[i] if i < len(pool) else None


def _line(what: str, diagnostics: dict, parameters: dict, second_order: Sequence[str] = ()) -> VerdictLine:
    """`second_order`: frequency names the model sees only at second order (its data.model)."""
    stem = re.sub(r"_(\d+)$", "", what)
    index = what[len(stem) + 1 :]
    label = _LABELS.get(stem, stem.replace("_", " "))
    if index:
        label = f"{label} {index}"
    line = VerdictLine(
        what=what,
        label=label,
        detected=diagnostics.get(f"{what}_detected") is True,
        broad=diagnostics.get(f"{what}_broad") is True,
        product=str(diagnostics.get(f"{what}_product") or ""),
        harmonic=str(diagnostics.get(f"{what}_harmonic") or ""),
        delta_loglike=as_number(diagnostics.get(f"{what}_delta_loglike")),
        threshold=as_number(diagnostics.get(f"{what}_threshold")),
        false_alarm_probability=as_number(diagnostics.get(f"{what}_false_alarm_probability")),
    )
    named = diagnostics.get(f"{what}_frequency_parameter")  # the line test's own frequency, when recorded
    name = named if isinstance(named, str) and named in parameters else _frequency_parameter(what, parameters)
    p = parameters.get(name) if name is not None else None
    if isinstance(p, dict):
        line.parameter = name
        line.value = as_number(p.get("median"))
        if math.isnan(line.value):
            line.value = as_number(p.get("map"))
        sd, q05, q95 = as_number(p.get("sd")), as_number(p.get("q05")), as_number(p.get("q95"))
        if math.isfinite(sd) and sd > 0:
            line.uncertainty, line.uncertainty_kind = sd, "sd"
        elif math.isfinite(q95 - q05):
            line.uncertainty, line.uncertainty_kind = 0.5 * (q95 - q05), "half the 90 % interval"
        units = p.get("units")
        line.units = units if isinstance(units, str) and units else "Hz"
        line.second_order = name in second_order or f"{name}[0]" in second_order
    return line


def lines_tested(summary: dict) -> list[VerdictLine]:
    """Every line of `summary["diagnostics"]` with a `{what}_detected` key, in the summary's order."""
    d = summary.get("diagnostics") if isinstance(summary.get("diagnostics"), dict) else {}
    params = summary.get("parameters") if isinstance(summary.get("parameters"), dict) else {}
    data = summary.get("data") if isinstance(summary.get("data"), dict) else {}
    model = data.get("model") if isinstance(data.get("model"), dict) else {}
    second = [n for n in model.get("second_order") or [] if isinstance(n, str)]
    return [_line(str(k)[: -len("_detected")], d, params, second) for k in d if str(k).endswith("_detected")]


def _convergence(summary: dict) -> tuple[float, float]:
    """(largest R-hat, smallest bulk or tail ESS) over the parameters, else the diagnostics'."""
    params = summary.get("parameters") if isinstance(summary.get("parameters"), dict) else {}
    rhats = [as_number(p.get("rhat")) for p in params.values() if isinstance(p, dict)]
    ess = [
        min(as_number(p.get("ess_bulk")), as_number(p.get("ess_tail"))) for p in params.values() if isinstance(p, dict)
    ]
    rhats = [r for r in rhats if math.isfinite(r)]
    ess = [e for e in ess if math.isfinite(e)]
    d = summary.get("diagnostics") if isinstance(summary.get("diagnostics"), dict) else {}
    rhat = max(rhats) if rhats else as_number(d.get("rhat_max"))
    e = min(ess) if ess else as_number(d.get("ess_min"))
    return rhat, e


def trust(summary: dict, lines: list[VerdictLine] | None = None) -> tuple[bool | None, list[str], str]:
    """(trusted, reasons, short): True when every check that applies passed, False when one
    failed, None when one could not be made (a detected line's frequency without an uncertainty
    is one); the reasons in words (failures first); a short form."""
    d = summary.get("diagnostics") if isinstance(summary.get("diagnostics"), dict) else {}
    failed: list[tuple[str, str]] = []  # (reason, short)
    unknown: list[tuple[str, str]] = []
    passed: list[tuple[str, str]] = []
    kind = approximation(summary)
    if kind is None:
        rhat, ess = _convergence(summary)
        converged = d.get("converged")
        numbers = f"R-hat {format_number(rhat, '.3f')}, ESS {format_number(ess, '.0f')}"
        if converged is False or rhat > RHAT_MAX or ess < ESS_MIN:
            failed.append(
                (
                    f"the sampler has not converged ({numbers}; needed: R-hat <= {RHAT_MAX}, ESS >= {ESS_MIN:.0f}): "
                    "run longer (--resume --max-steps N)",
                    f"not converged ({numbers})",
                )
            )
        elif converged is True or (math.isfinite(rhat) and math.isfinite(ess)):
            passed.append((f"the sampler converged ({numbers})", f"R-hat {format_number(rhat, '.3f')}"))
        else:
            unknown.append(("convergence not known (no R-hat or ESS in the result)", "convergence not known"))
    else:
        label = approximation_label(kind)
        if d.get("hessian_positive_definite") is False:
            failed.append(
                (
                    "the Hessian at the MAP is not positive definite: the intervals are conditional ones and "
                    "understate correlated parameters (run --method mcmc)",
                    "Hessian not positive definite",
                )
            )
        elif "importance_check" in d:
            failed.append(
                (
                    f"intervals from a {label} that fails its importance check ({d['importance_check']}): "
                    "they may be too narrow or off-centre (run --method mcmc to sample the posterior)",
                    "Laplace approximation unchecked",
                )
            )
        elif "psis_khat" in d:
            checked = (
                f"Pareto k {format_number(d['psis_khat'], '.2f')}, "
                f"{format_number(d.get('importance_ess'), '.0f')} effective draws"
            )
            passed.append((f"intervals from a {label} ({checked})", label))
        else:
            passed.append((f"intervals from a {label} (no sampler, so no R-hat)", label))
    checks = d.get("residual_checks")
    if not isinstance(checks, dict) or not checks:
        unknown.append(("residuals not checked", "residuals not checked"))
    else:
        white, normal = checks.get("white"), checks.get("normal")
        lags = format_number(checks.get("lags"), ".0f")
        lb = f"Ljung-Box p = {format_number(checks.get('ljung_box_p'), '.2g')} over {lags} lags"
        np_ = f"normality p = {format_number(checks.get('normality_p'), '.2g')}"
        alpha = as_number(checks.get("alpha"))
        if white is True and as_number(checks.get("ljung_box_p")) < alpha:  # detected, too small to matter
            lb += f", autocorrelations {format_number(checks.get('spectral_departure'), '.2f')} in all: immaterial"
        if normal is True and as_number(checks.get("normality_p")) < alpha:
            np_ += (
                f", skewness {format_number(checks.get('skewness'), '.3f')}, excess kurtosis "
                f"{format_number(checks.get('excess_kurtosis'), '.3f')}: immaterial"
            )
        if white is False:
            failed.append(
                (
                    f"the residuals are not white ({lb}): the model misses structure in the data",
                    "residuals not white",
                )
            )
        if normal is False:
            failed.append(
                (
                    f"the residuals are not Gaussian ({np_}): outliers or a noise the model does not describe",
                    "residuals not Gaussian",
                )
            )
        if white is True and normal is True:
            passed.append((f"residuals white ({lb}) and Gaussian ({np_})", "residuals white"))
        elif white is not False and normal is not False:
            unknown.append(("the residual checks are incomplete", "residuals not fully checked"))
    changes = d.get("line_stationarity")
    for label, entry in (changes if isinstance(changes, dict) else {}).items():
        if isinstance(entry, dict) and entry.get("stationary") is False:
            failed.append((describe_change(label, entry), f"{label.replace('_', ' ')} not stationary"))
    multimodal = d.get("multimodal")
    for n in multimodal if isinstance(multimodal, list) else []:
        failed.append((f"{n} is multimodal: the summary mixes separate modes", f"{n} multimodal"))
    capped = d.get("order_capped")
    for entry in capped if isinstance(capped, list) else []:
        if isinstance(entry, dict):
            kinds = str(entry.get("kind", "components"))
            unknown.append(
                (
                    f"the order search stopped at its cap of {entry.get('cap')} {kinds}, and one more "
                    f"({entry.get('what')}) lowers the BIC: the fit leaves out {kinds} the record holds",
                    f"more {kinds} than the cap of {entry.get('cap')}",
                )
            )
    sways = d.get("slow_sway")
    for entry in sways if isinstance(sways, list) else []:
        if isinstance(entry, dict):
            unknown.append(
                (
                    f"the pixels carry a slow line of {format_number(entry.get('cycles'), '.0f')} cycles in the record "
                    f"(detect's reading {format_number(entry.get('frequency'), '.4g')} +- "
                    f"{format_number(entry.get('resolution'), '.2g')} Hz): the joint fit of a sway of so few cycles is "
                    "not calibrated, its intervals can miss",
                    "a slow sway: intervals not calibrated",
                )
            )
    ambiguous = d.get("ambiguous")
    if isinstance(ambiguous, list) and ambiguous:
        failed.append(
            (
                "the data cannot tell this fit from another reading of the lines (see the warnings)",
                "another reading fits as well",
            )
        )
    for line in lines if lines is not None else lines_tested(summary):
        if line.detected and line.parameter is not None and not math.isfinite(line.uncertainty):
            unknown.append(
                (
                    f"the {line.label}'s frequency has no uncertainty (run --method map or mcmc for one)",
                    f"no uncertainty for the {line.label}",
                )
            )
    trusted = False if failed else (None if unknown else True)
    reasons = [r for r, _ in failed + unknown + passed]
    if trusted is True:
        short = f"fit trustworthy ({', '.join(s for _, s in passed)})"
    elif trusted is False:
        short = f"fit NOT trustworthy: {', '.join(s for _, s in failed)}"
    else:
        short = f"trust not decided ({', '.join(s for _, s in unknown + passed)})"
    return trusted, reasons, short


def verdict(summary: dict) -> Verdict:
    """The lines tested, the trust decision and one headline (`Verdict.headline`)."""
    lines = lines_tested(summary)
    trusted, reasons, short = trust(summary, lines)
    parts = [line.text() for line in lines] or ["no line tested"]
    return Verdict(lines, trusted, reasons, "; ".join([*parts, short]), short)

"""`vibinverse bench --calibration`: do the fit's 90 % intervals hold the truth 90 % of the time?

Each case simulates many data sets (`SETS`, 200; `--quick` `QUICK_SETS`) with the robustness
bench's simulator (`robustness_cases`: exact oscillators, the departures of real data), the
resonance's values drawn afresh for each data set (`ModeRanges`) so that no single lucky truth
decides, and fits each as a user would with the model that holds the departure, `vi.fit(series,
{"modal": {modes, lines, drift, noise, gain}})` (the order given: this bench checks the intervals,
`bench --robustness` the order search), default priors and method "auto" (the importance-sampled
Laplace approximation, emcee where its check fails). Every fit runs in its own process with a
wall-clock limit (`FIT_LIMIT_S`); one without an answer is counted, not scored.

Scores per case and parameter (`score`):

- coverage: the fraction of data sets whose 90 % interval (q05, q95) holds the truth, with its
  binomial standard error at the nominal 0.90, sqrt(0.09 / n), and z = (coverage - 0.90) / se;
- z RMS: the root mean square of (posterior mean - truth) / posterior sd, 1 for calibrated sds,
  and `far`: the fraction of data sets with |z| > 5 (a wrong reading, a mode and a line exchanged
  or a line on a noise peak, reported with a tight interval: a few of them make the z RMS large);
  `claimed`, the fraction of data sets whose fit called the parameter's component detected (its
  detection test), and `far|cl`, the far fraction among those: a far reading whose fit says "not
  detected" is one the user was told not to trust;
- where the misses fall (truth above or below the interval);
- `narrow80`: the coverage of the same intervals shrunk by 20 % about their median, what intervals
  20 % too narrow would give: the bench's power to see them (a run whose `narrow80` is not below
  0.85 has too few data sets to tell).

A case passes when its coverage lies within `BAND` (0.85-0.95).
"""

from __future__ import annotations

import json
import logging
import math
import re
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from vibinverse.bench.limited_processes import Job, Step, StepResult, run_jobs
from vibinverse.bench.robustness_cases import CASES, Case, Line, Mode, simulate
from vibinverse.bench.robustness_fit import quiet

LOG = logging.getLogger(__name__)

SETS = 200  # data sets per case (the n >= 200)
QUICK_SETS = 10  # with --quick: the same cases, se 0.095 (a smoke test of the machinery, not a verdict)
FIT_LIMIT_S = 300.0  # one fit's wall-clock limit (a fallback to emcee takes minutes on AR(1) noise)
QUICK_LIMIT_S = 60.0
NOMINAL = 0.90
BAND = (0.85, 0.95)  # coverage a case must show (the done-when)
NARROWER = 0.8  # `narrow80`: the intervals' half-widths times this
FAR_Z = 5.0  # `far`: |mean - truth| over this many posterior sds: a wrong reading with a tight interval


@dataclass(frozen=True)
class ModeRanges:
    """The range each data set's resonance is drawn from: frequency uniform (Hz), damping ratio and
    RMS log-uniform."""

    frequency: tuple[float, float] = (2.5, 5.0)
    damping_ratio: tuple[float, float] = (0.007, 0.03)
    rms: tuple[float, float] = (0.2, 0.45)

    def draw(self, rng: np.random.Generator) -> Mode:
        logu = lambda lo, hi: math.exp(rng.uniform(math.log(lo), math.log(hi)))
        return Mode(rng.uniform(*self.frequency), logu(*self.damping_ratio), logu(*self.rms))


@dataclass(frozen=True)
class DecayRanges:
    """A free decay's draw: frequency uniform (Hz), damping ratio log-uniform, a fixed initial
    amplitude, its phase uniform; it rings from `onset` (a fraction of the record: 0, rung before the
    record; else a blow there, nothing before it)."""

    frequency: tuple[float, float] = (8.0, 30.0)
    damping_ratio: tuple[float, float] = (0.003, 0.03)
    amplitude: float = 1.0
    onset: float = 0.0

    def draw(self, seed: int) -> tuple[float, float, float]:
        """(frequency, damping ratio, phase) of data set `seed`."""
        rng = np.random.default_rng([int(seed), 27_182])
        f = rng.uniform(*self.frequency)
        z = math.exp(rng.uniform(math.log(self.damping_ratio[0]), math.log(self.damping_ratio[1])))
        return f, z, rng.uniform(-math.pi, math.pi)

    def ring(self, t: np.ndarray, seed: int) -> np.ndarray:
        """The decay at the stamps t (exactly the free oscillator's motion from its onset)."""
        f, z, ph = self.draw(seed)
        w = 2.0 * math.pi * f
        t0 = t[0] + self.onset * (t[-1] - t[0])
        u = np.clip(t - t0, 0.0, None)
        out = self.amplitude * np.exp(-z * w * u) * np.cos(w * math.sqrt(1.0 - z * z) * u + ph)
        return np.where(t >= t0, out, 0.0)


@dataclass(frozen=True)
class CalibrationCase:
    """One way data depart (`base`, a robustness case, or a new one), the model that holds the
    departure (`noise`, `white`, `drift`, `gain` of the modal table; the order is the case's true one), and
    what varies from data set to data set: the resonance (`modes`, when the case has one) and the
    line's frequency (`line_band`, as fractions of the sampling rate, when given)."""

    name: str
    what: str
    base: Case
    noise: str = "white"
    white: bool = True
    drift: bool = False
    gain: bool = False
    modes: ModeRanges | None = ModeRanges()
    line_band: tuple[float, float] | None = None
    decay: DecayRanges | None = None

    def case(self, seed: int) -> Case:
        """The robustness case of data set `seed`: its resonance and line drawn."""
        rng = np.random.default_rng([int(seed), 31_337])
        c = self.base
        if self.modes is not None and len(c.modes) == 1:
            c = replace(c, modes=(self.modes.draw(rng),))
        if self.line_band is not None:
            f = c.fs * rng.uniform(*self.line_band)
            c = replace(c, lines=(Line(f, c.lines[0].amplitude), *c.lines[1:]))
        return c

    def table(self) -> dict[str, Any]:
        modes, lines = self.base.analyst_order()
        spec = {"modes": modes, "lines": lines, "drift": self.drift, "noise": self.noise, "gain": self.gain}
        if self.decay is not None:
            spec["decays"] = 1
        if not self.white:
            spec["white"] = False
        return {"modal": spec}


def truth_of(case: Case) -> dict[str, float]:
    """The scored parameters' true values: each mode's frequency, damping ratio and RMS (modes in
    ascending frequency, as the fit numbers them), each line's frequency and amplitude."""
    out: dict[str, float] = {}
    for i, m in enumerate(sorted(case.modes, key=lambda m: m.frequency)):
        out |= {f"modes[{i}].frequency": m.frequency, f"modes[{i}].damping_ratio": m.damping_ratio}
        out[f"modes[{i}].rms"] = m.rms
    for j, ln in enumerate(sorted(case.lines, key=lambda ln: ln.frequency)):
        out |= {f"lines[{j}].frequency": ln.frequency, f"lines[{j}].amplitude": ln.amplitude}
    return out


_R = CASES
#: the cases: the robustness departures (with the term that models each) and the few-cycle ones
CALIBRATION_CASES: dict[str, CalibrationCase] = {
    c.name: c
    for c in (
        CalibrationCase("clean", _R["clean"].what, _R["clean"]),
        CalibrationCase("gaps", _R["gaps"].what, _R["gaps"]),
        CalibrationCase("irregular", _R["irregular"].what, _R["irregular"]),
        CalibrationCase("ar1", _R["ar1"].what + "; fitted with AR(1) noise alone", _R["ar1"], noise="ar1", white=False),
        CalibrationCase("one_over_f", _R["one_over_f"].what + "; fitted with 1/f noise", _R["one_over_f"], noise="1/f"),
        CalibrationCase("drift", _R["drift"].what + "; fitted with a random-walk drift", _R["drift"], drift=True),
        CalibrationCase(
            "gain_drift", _R["gain_drift"].what + "; fitted with a gain drift", _R["gain_drift"], gain=True
        ),
        CalibrationCase("three_modes", _R["three_modes"].what + " (the same modes in every set)", _R["three_modes"]),
        CalibrationCase(
            "few_cycles",
            "a sway of 1.6-2.8 cycles: a line of 0.2-0.35 Hz (A 0.5) in 8 s at 24 fps, white noise 0.6",
            Case("few_cycles", "", fs=24.0, duration=8.0, modes=(), lines=(Line(0.25, 0.5),)),
            modes=None,
            line_band=(0.2 / 24.0, 0.35 / 24.0),
        ),
        CalibrationCase(
            "fifty_frames",
            "50 frames at 15 kfps: a line of 4-7.5 cycles (1.2-2.25 kHz, A 0.3), white noise 0.3",
            Case(
                "fifty_frames", "", fs=15_000.0, duration=50 / 15_000.0, modes=(), lines=(Line(1500.0, 0.3),), sigma=0.3
            ),
            modes=None,
            line_band=(0.08, 0.15),
        ),
        CalibrationCase(
            "free_decay",
            "a struck ring (8-30 Hz, zeta 0.003-0.03, A 1) from the record's start, 4 s at 200 Hz, white noise 0.3",
            Case("free_decay", "", fs=200.0, duration=4.0, modes=(), lines=(), sigma=0.3),
            modes=None,
            decay=DecayRanges(),
        ),
        CalibrationCase(
            "hammer_blow",
            "a blow at a quarter of a 4 s record at 200 Hz: the same ring, nothing before it, white noise 0.3",
            Case("hammer_blow", "", fs=200.0, duration=4.0, modes=(), lines=(), sigma=0.3),
            modes=None,
            decay=DecayRanges(onset=0.25),
        ),
    )
}


# ------------------------------------------------------------------------------ one data set's fit
def fit_set(name: str, seed: int, method: str = "auto") -> dict[str, Any]:
    """Data set `seed` of case `name` simulated and fitted (by `method`): {"truth", "estimates":
    {parameter: [q05, q95, median, mean, sd]}, "approximation"} (run in a process of its own by
    `run`)."""
    import vibinverse as vi

    cal = CALIBRATION_CASES[name]
    case = cal.case(seed)
    data = simulate(case, seed)
    y, truth = data.intensity, truth_of(case)
    if cal.decay is not None:  # the ring added, its frequency and damping scored (not its amplitude:
        y = y + cal.decay.ring(data.time, seed)  # the fit's is the scale of a Rayleigh law)
        f, z, _ = cal.decay.draw(seed)
        truth |= {"decays[0].frequency": f, "decays[0].damping_ratio": z}
    summary = vi.fit(vi.series(data.time, y), cal.table(), method=method).summary()
    p = summary["parameters"]
    estimates = {k: [p[k][q] for q in ("q05", "q95", "median", "mean", "sd")] for k in truth if k in p}
    diag = summary.get("diagnostics") or {}
    detected = {k[: -len("_detected")]: bool(v) for k, v in diag.items() if k.endswith("_detected")}
    return {
        "truth": truth,
        "estimates": estimates,
        "approximation": str(summary.get("approximation") or "emcee"),
        "detected": detected,
    }


def detection_label(name: str) -> str | None:
    """The detection test of a parameter's component ("modes[0].rms" -> "mode_0", "lines[1]..." ->
    "line_1"); None for a parameter of no component."""
    m = re.match(r"(modes|lines|decays)\[(\d+)\]\.", name)
    return f"{m.group(1)[:-1]}_{m.group(2)}" if m else None


def _job(name: str, seed: int, limit_s: float, fit: Callable[[str, int], dict[str, Any]], log: Path | None) -> Job:
    res: StepResult = yield Step("fit", fit, (name, seed), limit_s, f"{name} #{seed}")
    value = res.value or {}
    record = {"case": name, "seed": seed, "status": res.status, "seconds": res.seconds, "error": res.error, **value}
    if log is not None:  # as each fit ends: a run stopped early keeps what it did
        with open(log, "a") as fh:
            fh.write(json.dumps(record) + "\n")
    return [record]


# ------------------------------------------------------------------------------------ the scores
def score(records: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per case and parameter, over the records that have an answer: n, coverage, se, z, z RMS,
    far, truth above / below, narrow80 and whether the coverage is within BAND (module docstring)."""
    rows = []
    for case in dict.fromkeys(r["case"] for r in records):
        ok = [r for r in records if r["case"] == case and r["status"] == "ok"]
        names = list(dict.fromkeys(k for r in ok for k in r["estimates"]))
        for name in names:
            have = [r for r in ok if name in r["estimates"]]
            truth = np.array([r["truth"][name] for r in have])
            lo, hi, med, mean, sd = (np.array([r["estimates"][name][i] for r in have], float) for i in range(5))
            n = truth.size
            held = (lo <= truth) & (truth <= hi)
            lo80, hi80 = med - NARROWER * (med - lo), med + NARROWER * (hi - med)
            cover = float(held.mean())
            se = math.sqrt(NOMINAL * (1 - NOMINAL) / n)
            z = np.where(sd > 0, (mean - truth) / np.where(sd > 0, sd, 1.0), np.nan)
            label = detection_label(name)
            said = [r.get("detected", {}).get(label) if label else None for r in have]
            claimed = np.array([v is True for v in said])
            rows.append(
                {
                    "case": case,
                    "parameter": name,
                    "n": n,
                    "coverage90": cover,
                    "se": se,
                    "z": (cover - NOMINAL) / se,
                    "z_rms": float(np.sqrt(np.nanmean(z**2))),
                    "far": float(np.mean(np.abs(z) > FAR_Z)),
                    # far among the data sets whose fit claimed the component detected (None: no
                    # record says): a far reading the fit itself calls undetected is no broken promise
                    "far_claimed": float(np.sum((np.abs(z) > FAR_Z) & claimed) / max(int(claimed.sum()), 1))
                    if any(v is not None for v in said)
                    else None,
                    "claimed": float(claimed.mean()) if any(v is not None for v in said) else None,
                    "truth_above": float(np.mean(truth > hi)),
                    "truth_below": float(np.mean(truth < lo)),
                    "narrow80": float(np.mean((lo80 <= truth) & (truth <= hi80))),
                    "within_band": BAND[0] <= cover <= BAND[1],
                }
            )
    return rows


def case_summary(records: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per case: data sets, answers, errors, no answer within the limit, median seconds a fit, and
    what formed the intervals (importance, laplace, emcee: counts)."""
    out = []
    for case in dict.fromkeys(r["case"] for r in records):
        rs = [r for r in records if r["case"] == case]
        ok = [r for r in rs if r["status"] == "ok"]
        out.append(
            {
                "case": case,
                "sets": len(rs),
                "answered": len(ok),
                "errors": sum(r["status"] == "error" for r in rs),
                "timeouts": sum(r["status"] == "timeout" for r in rs),
                "median_seconds": float(np.median([r["seconds"] for r in ok])) if ok else None,
                "posterior": dict(Counter(r.get("approximation", "") for r in ok)),
                "first_error": next((r["error"] for r in rs if r["status"] == "error"), ""),
            }
        )
    return out


# ------------------------------------------------------------------------------------ the run
def run(
    quick: bool = False,
    cases: Sequence[str] | None = None,
    workers: int = 2,
    sets: int | None = None,
    limit_s: float | None = None,
    fit: Callable[[str, int], dict[str, Any]] = fit_set,
    records: Path | None = None,
) -> dict[str, Any]:
    """Every data set of every case (default: all of `CALIBRATION_CASES`; `sets` per case, default
    SETS, QUICK_SETS with `quick`), `workers` fits at once, each within `limit_s` (default
    FIT_LIMIT_S, QUICK_LIMIT_S with `quick`), after one untimed MAP fit in this process (the kernels
    compiled once, not in every forked process). `records`: a JSON-lines file each fit's record
    is appended to as it ends. Returns
    {"rows": `score`, "cases": `case_summary`, "records": every fit, "settings", "seconds"}."""
    names = list(cases) if cases is not None else list(CALIBRATION_CASES)
    for c in names:
        if c not in CALIBRATION_CASES:
            raise ValueError(f"cases: {c!r}; allowed: {', '.join(CALIBRATION_CASES)}")
    n = int(sets) if sets is not None else (QUICK_SETS if quick else SETS)
    limit_s = float(limit_s) if limit_s is not None else (QUICK_LIMIT_S if quick else FIT_LIMIT_S)
    t0 = time.perf_counter()
    LOG.info(f"calibration: {len(names)} case(s) x {n} data sets, {workers} process(es), fit limit {limit_s:g} s")
    if fit is fit_set and names:  # compiled and imported once here, for every forked fit to inherit
        with quiet():  # a MAP: the kernels without the sampler (emcee takes minutes on 1/f noise)
            fit_set(names[0], n, method="map")
    jobs = [_job(c, seed, limit_s, fit, records) for c in names for seed in range(n)]
    records = [rec for rows in run_jobs(jobs, workers) for rec in rows]
    settings = {
        "quick": quick,
        "sets": dict.fromkeys(names, n),
        "fit_limit_s": limit_s,
        "workers": workers,
        "band": list(BAND),
        "cases": {c: CALIBRATION_CASES[c].what for c in names},
        "models": {c: CALIBRATION_CASES[c].table()["modal"] for c in names},
    }
    return {
        "rows": score(records),
        "cases": case_summary(records),
        "records": records,
        "settings": settings,
        "seconds": time.perf_counter() - t0,
    }


def combine(*results: dict[str, Any]) -> dict[str, Any]:
    """Runs of different cases (say the fast cases at 200 data sets and the slow ones at fewer) as
    one result: their records together, scored again; settings per case from the run that had it."""
    records = [rec for r in results for rec in r["records"]]
    settings: dict[str, Any] = {"quick": any(r["settings"]["quick"] for r in results)}
    for key in ("sets", "cases", "models"):
        settings[key] = {k: v for r in results for k, v in r["settings"][key].items()}
    settings["fit_limit_s"] = {c: r["settings"]["fit_limit_s"] for r in results for c in r["settings"]["cases"]}
    settings["workers"], settings["band"] = results[0]["settings"]["workers"], list(BAND)
    seconds = sum(r["seconds"] for r in results)
    return {
        "rows": score(records),
        "cases": case_summary(records),
        "records": records,
        "settings": settings,
        "seconds": seconds,
    }


def without_records(result: dict[str, Any]) -> dict[str, Any]:
    """The result without its per-fit records (what the table and the figure use)."""
    return {k: v for k, v in result.items() if k != "records"}


def sets_text(result: dict[str, Any]) -> str:
    """'200 data sets per case' or '200 data sets per case (ar1, one_over_f: 20)'."""
    sets = result.get("settings", {}).get("sets", {})
    if not isinstance(sets, dict) or not sets:
        return f"{sets or '?'} data sets per case"
    counts = Counter(sets.values())
    main = counts.most_common(1)[0][0]
    others = ", ".join(f"{', '.join(c for c, v in sets.items() if v == n)}: {n}" for n in counts if n != main)
    return f"{main} data sets per case" + (f" ({others})" if others else "")


def _opt(v: float | None, width: int) -> str:
    return f"{v:>{width}.3f}" if v is not None else f"{'-':>{width}}"


def table(result: dict[str, Any]) -> str:
    """The coverage table: a row per case and parameter, then a line per case (answers, time, what
    formed the intervals)."""
    lines = [
        f"{'case':<13}{'parameter':<24}{'n':>4}{'cover90':>9}{'se':>7}{'z':>7}{'zRMS':>8}{'far':>6}"
        f"{'claimed':>8}{'far|cl':>7}{'above':>7}{'below':>7}{'narrow80':>9}  in {BAND[0]:.2f}-{BAND[1]:.2f}"
    ]
    for r in result["rows"]:
        lines.append(
            f"{r['case']:<13}{r['parameter']:<24}{r['n']:>4}{r['coverage90']:>9.3f}{r['se']:>7.3f}{r['z']:>7.1f}"
            f"{r['z_rms']:>8.3g}{r['far']:>6.3f}{_opt(r.get('claimed'), 8)}{_opt(r.get('far_claimed'), 7)}"
            f"{r['truth_above']:>7.2f}{r['truth_below']:>7.2f}{r['narrow80']:>9.3f}"
            f"  {'yes' if r['within_band'] else 'NO'}"
        )
    lines.append("")
    for c in result["cases"]:
        post = ", ".join(f"{k} {v}" for k, v in c["posterior"].items())
        sec = f"{c['median_seconds']:.1f} s a fit" if c["median_seconds"] is not None else "no answer"
        lost = f"; {c['errors']} errors, {c['timeouts']} without an answer" if c["errors"] or c["timeouts"] else ""
        first = f" (first: {c['first_error']})" if c["first_error"] else ""
        lines.append(f"{c['case']:<13}{c['answered']}/{c['sets']} answered, {sec}, intervals from {post}{lost}{first}")
    return "\n".join(lines)


def plot(result: dict[str, Any], path: Path) -> None:
    """Coverage per case and parameter with +-2 se, the 0.85-0.95 band shaded; beside it the z RMS."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = result["rows"]
    labels = [f"{r['case']}: {r['parameter']}" for r in rows]
    y = np.arange(len(rows))[::-1]
    fig, (ax, az) = plt.subplots(1, 2, figsize=(11, 0.28 * len(rows) + 1.6), sharey=True, width_ratios=(3, 1))
    ax.axvspan(*BAND, color="tab:green", alpha=0.15, label=f"{BAND[0]:.2f}-{BAND[1]:.2f}")
    ax.axvline(NOMINAL, color="k", lw=0.8)
    colours = ["tab:blue" if r["within_band"] else "tab:red" for r in rows]
    ax.errorbar([r["coverage90"] for r in rows], y, xerr=[2 * r["se"] for r in rows], fmt="none", ecolor="0.6", lw=1)
    ax.scatter([r["coverage90"] for r in rows], y, c=colours, s=18, zorder=3)
    ax.set_yticks(y, labels, fontsize=7)
    ax.set_xlabel("coverage of the 90 % intervals (+-2 se)")
    ax.set_xlim(min(0.5, *(r["coverage90"] - 0.05 for r in rows)) if rows else 0.5, 1.0)
    ax.legend(loc="lower left", fontsize=7)
    az.axvline(1.0, color="k", lw=0.8)
    az.scatter([r["z_rms"] for r in rows], y, c=colours, s=18)
    az.set_xlabel("z RMS (1: calibrated sd)")
    az.set_xscale("log")
    fig.suptitle(f"Calibration: {sets_text(result)}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)

"""`vibinverse bench --robustness`: our fits against peers on data that depart from the clean
simulation the way real measurements do (gaps, irregular stamps, coloured sensor noise, drift, a
drifting gain, a weak line next to the resonance, several modes, noise alone).

The cases and their simulator are in `robustness_cases`, what the data can decide in
`robustness_oracle`, the peers in `robustness_peers`, what a fit reports in `robustness_fit`.

Fitters (`Fitter`: `name`, `fit(t, y, order=None) -> FitOutcome`):

- ours (`ModalFitter`): the scene-less modal model through the public API, the order chosen from
  the data by BIC (`vi.fit(vi.series(t, y), None, method="auto")`: what a user gets, the
  importance-sampled Laplace approximation, emcee where its check fails; the outcome records
  which formed the intervals), and "ours-fixed", the order an analyst expects
  (`{"modal": {"modes": K, "lines": L, "drift": True, "noise": "ar1"}}`);
- the peers (`robustness_peers`): celerite2, celerite2-ou and SSI-cov.

The peers fit the order they are given: the true one (for noise_only, the clean case's: what an
analyst expecting the clean case would fit); SSI-cov reports whatever its stabilization diagram
shows. Ours with BIC chooses its own order. `run(quick=True)` runs 6 data sets per case at half
the durations with ours, celerite2 and SSI-cov; the full run 50 with all five.

Metrics per case, method and parameter over N data sets (`score`): the median relative error of
the mode frequencies and damping ratios and of the line frequencies and amplitudes (true and fitted
components matched by nearest frequency, Hungarian assignment, within 5 % relative; a true
component without a fitted one that close is "missed"), the 90 % interval coverage over the matched
components that have an interval, with its binomial standard error, the line detection rate (true
lines matched by a fitted line that passed its detection test), the false-detection rate (data sets
in which a component that matches no true one was reported detected: for noise_only, any), the
failures and the wall time per fit.

The rows also carry what the data can decide (`robustness_oracle.oracle`): the fractions of the
true components whose gain in log-likelihood passes the order search's threshold.

The scene column (`robustness_scene`, `vibinverse bench --robustness --scene`): the same departures
on data simulated from roof_frame.toml, fitted with that scene; `with_scene` puts its result under
"scene" beside the modal columns, and `table` prints it below theirs.
"""

from __future__ import annotations

import contextlib
import dataclasses
import importlib.util
import logging
import math
import time
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from vibinverse.bench.robustness_cases import CASES, simulate
from vibinverse.bench.robustness_fit import FitOutcome, Fitter, ModalFitter
from vibinverse.bench.robustness_oracle import oracle
from vibinverse.bench.robustness_peers import Celerite2Fitter, SSIFitter

LOG = logging.getLogger(__name__).info

MATCH_TOL = 0.05  # a fitted component matches a true one within 5 % of its frequency
QUICK_SETS = 6  # data sets per case with `quick` (8 took 5 min 10 s on 2 cores with the line/resonance readings)


def modal_available() -> str | None:
    """None when our scene-less modal fit can run, else why not."""
    for mod in ("vibinverse.models.modal", "vibinverse.model_order"):
        if importlib.util.find_spec(mod) is None:
            return f"{mod} is not there yet"
    return None


FITTERS = ("ours", "ours-fixed", "celerite2", "celerite2-ou", "ssi-cov")
QUICK_FITTERS = ("ours", "celerite2", "ssi-cov")


def available_fitters(names: Sequence[str] | None = None, method: str = "auto") -> tuple[list[Fitter], dict[str, str]]:
    """(the fitters that can run, {name: why not} of those skipped). Names: ours, ours-fixed,
    celerite2, celerite2-ou (with an Ornstein-Uhlenbeck noise term), ssi-cov (default: all). `method` is
    ours'; ours-fixed fits by MAP + Laplace (the comment below says why)."""
    names = list(names) if names is not None else list(FITTERS)
    fitters: list[Fitter] = []
    skipped: dict[str, str] = {}
    for n in names:
        if n in ("ours", "ours-fixed"):
            why = modal_available()
            if why:
                skipped[n] = why
            else:
                # the analyst's order (drift and AR(1) forced on) by MAP + Laplace: on data without them
                # their parameters are unidentified and a sampler pays (auto on clean: 203 s a fit)
                fitters.append(ModalFitter(method=method if n == "ours" else "map", fixed=n == "ours-fixed"))
        elif n in ("celerite2", "celerite2-ou"):
            if importlib.util.find_spec("celerite2") is None:
                skipped[n] = "celerite2 is not installed (pip install '.[peers]')"
            else:
                fitters.append(Celerite2Fitter(name=n, red_noise=n == "celerite2-ou"))
        elif n == "ssi-cov":
            if importlib.util.find_spec("pyoma2") is None:
                skipped[n] = "pyOMA2 is not installed (pip install '.[peers]')"
            else:
                fitters.append(SSIFitter())
        else:
            raise ValueError(f"fitter: {n!r}; allowed: {', '.join(FITTERS)}")
    return fitters, skipped


# ------------------------------------------------------------------ metrics


def match(true_f: Sequence[float], fit_f: Sequence[float], tol: float = MATCH_TOL) -> list[int | None]:
    """For each true frequency the index of the fitted one assigned to it (Hungarian assignment on
    the relative frequency difference), or None when none lies within `tol` of it."""
    from scipy.optimize import linear_sum_assignment

    out: list[int | None] = [None] * len(true_f)
    if not len(true_f) or not len(fit_f):
        return out
    tf, ff = np.asarray(true_f, float), np.asarray(fit_f, float)
    cost = np.abs(ff[None, :] - tf[:, None]) / tf[:, None]
    cost = np.where(np.isfinite(cost), cost, 1e9)
    rows, cols = linear_sum_assignment(cost)
    for r, c in zip(rows, cols):
        if cost[r, c] <= tol:
            out[int(r)] = int(c)
    return out


PARAMS = {
    "mode frequency": ("modes", "frequency", "frequencies", "frequency"),
    "mode damping": ("modes", "damping_ratio", "damping_ratios", "damping_ratio"),
    "line frequency": ("lines", "frequency", "line_frequencies", "frequency"),
    "line amplitude": ("lines", "amplitude", "line_amplitudes", "amplitude"),
}


def _binomial(hits: list[bool]) -> tuple[float | None, float | None]:
    if not hits:
        return None, None
    p = float(np.mean(hits))
    return p, math.sqrt(p * (1.0 - p) / len(hits))


Z90 = 1.6448536269514722  # the standard normal's 95 % point: a 90 % interval is +-Z90 sd
Z_MAD = 1.482602218505602  # sd / median absolute deviation of a normal


def interval_z(true: float, interval: tuple[float, float]) -> float:
    """The truth's distance from a 90 % interval's centre in the interval's own sd (half-width /
    Z90): |z| <= Z90 exactly when the interval holds the truth. Over many data sets these are
    standard normal when the intervals are the right width and Gaussian; their robust sd says
    whether the typical interval is too wide (< 1) or too narrow (> 1), and the fraction beyond
    2 Z90 (0.1 % for a normal) whether the misses are a few far ones (a posterior with heavier
    tails than its intervals)."""
    lo, hi = interval
    return (true - 0.5 * (lo + hi)) / (0.5 * (hi - lo) / Z90)


def score(case: str, method: str, truths: Sequence[dict], outcomes: Sequence[FitOutcome]) -> list[dict]:
    """The rows of one case and method over its data sets (module docstring): one per parameter
    the case has (mode frequency, mode damping, line frequency, line amplitude), or one with
    param "-" when it has no component (noise_only). Each row also has `found`, the fraction of
    the true components of its kind (mode rows: modes, line rows: lines) that a fitted one matched,
    and, when the truths carry their `oracle`, `oracle_detection` and `oracle_known_frequency`: the
    fraction of those components (over every data set, failed fits included) whose oracle gain
    passes its threshold, and its threshold at a known frequency; `oracle_refit_detection` the
    same with the refitted gain (`oracle(refit=True)`; None where there is none). `z_robust_sd`
    and `far_miss` describe how the intervals miss (`interval_z`): the robust sd (1.4826 x median
    |z|) and the fraction with |z| > 2 Z90."""
    n = len(outcomes)
    good = [(tr, o) for tr, o in zip(truths, outcomes) if not o.failed]
    matches = []  # per data set: (mode matches, line matches)
    line_hits: list[bool] = []
    false_hits: list[bool] = []
    for tr, o in good:
        mm = match([m["frequency"] for m in tr["modes"]], o.frequencies)
        lm = match([ln["frequency"] for ln in tr["lines"]], o.line_frequencies)
        matches.append((mm, lm))
        for j in lm:
            line_hits.append(j is not None and bool(_at(o.lines_detected, j, True)))
        # a detected component that matches no true one: modes and lines pooled (a line fitted as
        # a mode is still found), so the unmatched are those matching neither list
        true_all = [m["frequency"] for m in tr["modes"]] + [ln["frequency"] for ln in tr["lines"]]
        spurious = False
        for freqs, det in ((o.frequencies, o.modes_detected), (o.line_frequencies, o.lines_detected)):
            for f, d in zip(freqs, det if det else [True] * len(freqs)):
                if d and not any(abs(f - tf) <= MATCH_TOL * tf for tf in true_all):
                    spurious = True
        false_hits.append(spurious)
    common = {
        "case": case,
        "method": method,
        "n": n,
        "n_failed": n - len(good),
        "line_detection": _binomial(line_hits)[0],
        "false_detection": _binomial(false_hits)[0],
        "seconds": float(np.mean([o.seconds for o in outcomes])) if outcomes else None,
    }
    truth0 = truths[0] if truths else {"modes": [], "lines": []}
    rows = []
    for param, (kind, key, attr, iname) in PARAMS.items():
        if not truth0[kind]:
            continue
        errors, covers, zs, missed, total = [], [], [], 0, 0
        for (tr, o), (mm, lm) in zip(good, matches):
            assigned = mm if kind == "modes" else lm
            values = getattr(o, attr)
            for comp, j in zip(tr[kind], assigned):
                total += 1
                if j is None:
                    missed += 1
                    continue
                true = comp[key]
                errors.append(abs(values[j] - true) / abs(true))
                iv = o.intervals.get(f"{kind}[{j}].{iname}")
                if iv is not None:
                    covers.append(bool(iv[0] <= true <= iv[1]))
                    if iv[1] > iv[0]:
                        zs.append(interval_z(true, iv))
        cov, se = _binomial(covers)
        az = np.abs(zs)
        rows.append(
            {
                **common,
                "param": param,
                "n_missed": missed,
                "found": 1.0 - missed / total if total else None,
                "oracle_detection": _oracle_rate(truths, kind, "detected"),
                "oracle_known_frequency": _oracle_rate(truths, kind, "detected_known"),
                "oracle_refit_detection": _oracle_rate(truths, kind, "detected_refit"),
                "median_rel_error": float(np.median(errors)) if errors else None,
                "coverage90": cov,
                "coverage_se": se,
                "n_intervals": len(covers),
                "z_robust_sd": float(Z_MAD * np.median(az)) if zs else None,
                "far_miss": float(np.mean(az > 2.0 * Z90)) if zs else None,
            }
        )
    if not rows:
        rows.append(
            {
                **common,
                "param": "-",
                "n_missed": 0,
                "found": None,
                "oracle_detection": None,
                "oracle_known_frequency": None,
                "oracle_refit_detection": None,
                "median_rel_error": None,
                "coverage90": None,
                "coverage_se": None,
                "n_intervals": 0,
                "z_robust_sd": None,
                "far_miss": None,
            }
        )
    return rows


def _oracle_rate(truths: Sequence[dict], kind: str, key: str) -> float | None:
    """The fraction of the true components of `kind` whose oracle test `key` passed (None: no oracle)."""
    hits = [o.get(key) for tr in truths for o in tr.get("oracle") or [] if o["kind"] == kind]
    return _binomial([h for h in hits if h is not None])[0]


def _at(seq: Sequence, i: int, default):
    return seq[i] if i < len(seq) else default


# ------------------------------------------------------------------ the run


def _job(job: tuple) -> list[dict]:
    """One data set, every fitter: [{"method", "outcome"}] (a worker's unit of work)."""
    case, seed, quick, fitters, with_oracle, refit = job
    from threadpoolctl import threadpool_limits

    data = simulate(case, seed, quick)
    order = CASES[case].analyst_order()
    out = []
    with threadpool_limits(1):
        truth = {**data.truth, "oracle": oracle(case, seed, quick, refit=refit)} if with_oracle else data.truth
        for f in fitters:
            out.append({"method": f.name, "outcome": f.fit(data.time, data.intensity, order), "truth": truth})
    return out


def fit_record(case: str, job_fit: dict) -> dict:
    """One fit of the run as JSON: case, seed, method, the truth (oracle gains included) and the
    fitter's outcome (`FitOutcome`'s fields): what a later look at one case needs without a rerun."""
    return {
        "case": case,
        "seed": job_fit["truth"]["seed"],
        "method": job_fit["method"],
        "truth": job_fit["truth"],
        "outcome": dataclasses.asdict(job_fit["outcome"]),
    }


def run(
    quick: bool = False,
    n: int | None = None,
    cases: Sequence[str] | None = None,
    fitters: Sequence[str] | Sequence[Fitter] | None = None,
    workers: int = 2,
    method: str = "auto",
    seed0: int = 0,
    log=LOG,
    with_oracle: bool = True,
    oracle_refit: bool = True,
) -> dict[str, Any]:
    """The comparison: N data sets per case (`n`; default 50, or QUICK_SETS (6) with `quick`, which also halves
    every record's duration), each fitted by every fitter (names or Fitter objects; default: ours,
    ours-fixed, celerite2 and ssi-cov, without ours-fixed with `quick`; one whose package or code
    is missing is skipped with a note), `workers` processes over the data sets; `with_oracle`:
    each data set's `oracle` too (~0.02 s a data set, 2-3 s for the dense one_over_f and
    gain_drift at 4000 samples), with `oracle_refit` its refitted gains (0.3-1 s more a data set
    where the Kalman filter is exact). Returns {"rows", "fits", "skipped", "notes", "settings",
    "seconds"}, JSON-able; rows as `score` makes them, fits one `fit_record` per fit."""
    t_start = time.perf_counter()
    n = n if n is not None else (QUICK_SETS if quick else 50)
    if fitters is None:
        fitters = QUICK_FITTERS if quick else FITTERS
    cases = list(cases) if cases is not None else list(CASES)
    for c in cases:
        if c not in CASES:
            raise ValueError(f"case: {c!r}; allowed: {', '.join(CASES)}")
    if fitters is None or all(isinstance(f, str) for f in fitters):
        fl, skipped = available_fitters(fitters, method)
    else:
        fl, skipped = list(fitters), {}
    for name, why in skipped.items():
        log(f"  {name}: skipped ({why})")
    jobs = [(c, seed0 + s, quick, fl, with_oracle, oracle_refit) for c in cases for s in range(n)]
    rows: list[dict] = []
    fits: list[dict] = []
    notes: set[str] = set()
    with contextlib.ExitStack() as stack:
        if workers > 1 and len(jobs) > 1:
            import multiprocessing as mp
            from concurrent.futures import ProcessPoolExecutor

            pool = stack.enter_context(ProcessPoolExecutor(workers, mp_context=mp.get_context("fork")))
            results = pool.map(_job, jobs)  # in order: each case is scored as soon as its data sets are done
        else:
            results = map(_job, jobs)
        for c in cases:
            per = [next(results) for _ in range(n)]
            rows += _case_rows(c, fl, per, notes, log)
            fits += [fit_record(c, x) for r in per for x in r]
    return {
        "rows": rows,
        "fits": fits,
        "skipped": skipped,
        "notes": sorted(notes),
        "seconds": time.perf_counter() - t_start,
        "settings": {
            "quick": quick,
            "n": n,
            "seeds": [seed0, seed0 + n - 1],
            "cases": {c: CASES[c].what for c in cases},
            "durations_s": {c: CASES[c].span(quick) for c in cases},
            "methods": [f.name for f in fl],
            "method_ours": method,
            "match_tolerance": MATCH_TOL,
            "workers": workers,
            "oracle": with_oracle,
            "oracle_refit": with_oracle and oracle_refit,
        },
    }


def _case_rows(case: str, fitters: Sequence[Fitter], per: list[list[dict]], notes: set[str], log) -> list[dict]:
    """The rows of one case from its data sets' fits; its notes (resampling, failures) to `notes`."""
    rows = []
    for f in fitters:
        fits = [x for r in per for x in r if x["method"] == f.name]
        outcomes = [x["outcome"] for x in fits]
        new = score(case, f.name, [x["truth"] for x in fits], outcomes)
        rows += new
        notes.update(f"{f.name} on {case}: {o.note}" for o in outcomes if o.note and not o.failed)
        kinds = Counter(o.posterior for o in outcomes if o.posterior and not o.failed)
        if len(kinds) > 1:  # e.g. importance sampling with emcee where its check failed
            notes.add(f"{f.name} on {case}: intervals by " + ", ".join(f"{k} in {v}" for k, v in kinds.most_common()))
        fails = sorted({o.note for o in outcomes if o.failed})
        if fails:
            notes.add(f"{f.name} on {case}: {len(fails)} kind(s) of failure: {'; '.join(fails[:3])}")
        r = new[0]
        log(
            f"  {case:<12} {f.name:<11} {len(outcomes):>3} data sets, {r['seconds']:.2f} s per fit, "
            f"{r['n_failed']} failed"
        )
    return rows


def with_scene(result: dict[str, Any] | None, scene: dict[str, Any]) -> dict[str, Any]:
    """`result` (an earlier run's, or None) with the scene column (`robustness_scene.run`) under
    "scene": a scene run adds to robustness.json instead of replacing its modal columns."""
    return {**(result or {}), "scene": scene}


def table(result: dict[str, Any]) -> str:
    """The rows as a fixed-width text table (with the skipped peers and the notes below it):
    n_iv is the number of intervals the coverage rests on; z_rsd and far how they miss (`score`:
    the robust sd of the truths' distances from the intervals' centres in the intervals' sd, and
    the fraction of those beyond twice the 90 % half-width); missed the true components no fitted
    one matched, found the fraction matched, failed the failed fits over the data sets; oracle,
    or_kf and or_rf what the data can decide (`oracle`: the fraction of the row's components, modes
    or lines, that pass the order search's threshold at the true parameters, at a known frequency,
    and with both orders refitted), approximate upper bounds on found (mode rows) and line_det
    (line rows)."""
    fmt = lambda v, f: format("-", f">{f.split('.')[0]}") if v is None else format(v, f)
    lines = [
        f"{'case':<12}{'method':<11}{'parameter':<16}{'med_rel_err':>12}{'cover90':>8}{'+-se':>6}{'n_iv':>5}{'z_rsd':>6}{'far':>5}"
        f"{'missed':>7}{'found':>6}{'line_det':>9}{'oracle':>7}{'or_kf':>6}{'or_rf':>6}{'false_det':>10}{'failed':>8}{'s/fit':>8}"
    ]
    for r in result.get("rows", []):
        lines.append(
            f"{r['case']:<12}{r['method']:<11}{r['param']:<16}{fmt(r['median_rel_error'], '12.2e')}"
            f"{fmt(r['coverage90'], '8.2f')}{fmt(r['coverage_se'], '6.2f')}{r['n_intervals']:>5}"
            f"{fmt(r.get('z_robust_sd'), '6.2f')}{fmt(r.get('far_miss'), '5.2f')}{r['n_missed']:>7}"
            f"{fmt(r.get('found'), '6.2f')}{fmt(r['line_detection'], '9.2f')}"
            f"{fmt(r.get('oracle_detection'), '7.2f')}{fmt(r.get('oracle_known_frequency'), '6.2f')}"
            f"{fmt(r.get('oracle_refit_detection'), '6.2f')}"
            f"{fmt(r['false_detection'], '10.2f')}{r['n_failed']:>5}/{r['n']:<2}{fmt(r['seconds'], '8.2f')}"
        )
    for name, why in result.get("skipped", {}).items():
        lines.append(f"skipped {name}: {why}")
    lines += [f"note: {n}" for n in result.get("notes", [])]
    if result.get("scene"):
        from vibinverse.bench.robustness_scene import table as scene_table

        lines += ["", "scene column (roof_frame.toml):", scene_table(result["scene"])]
    return "\n".join(lines)


def plot(rows: list[dict], path: Path) -> None:
    """Median relative error (top, log scale) and 90 % coverage with its standard error (middle,
    the 0.9 target dashed) per case, one column per parameter, methods side by side; below, the
    detection panels: the fraction of the true modes found and of the true lines detected, with
    the oracle's rates (what the data can decide: a black diamond; an open one at a known
    frequency; a grey one refitted)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    params = [p for p in PARAMS if any(r["param"] == p for r in rows)] or list(PARAMS)
    methods = list(dict.fromkeys(r["method"] for r in rows))
    ncol = max(2, len(params))
    fig = plt.figure(figsize=(4.6 * ncol, 12), constrained_layout=True)
    grid = fig.add_gridspec(3, ncol)
    axes = np.array([[fig.add_subplot(grid[i, j]) for j in range(len(params))] for i in range(2)])
    width = 0.8 / max(1, len(methods))
    for col, p in enumerate(params):
        sel = [r for r in rows if r["param"] == p]
        cases = list(dict.fromkeys(r["case"] for r in sel))
        x = np.arange(len(cases))
        shown = False  # a positive error to put on the log scale
        for k, m in enumerate(methods):
            by = {r["case"]: r for r in sel if r["method"] == m}
            err = [by[c]["median_rel_error"] if c in by and by[c]["median_rel_error"] else np.nan for c in cases]
            shown |= any(np.isfinite(err))
            cov = [by[c]["coverage90"] if c in by and by[c]["coverage90"] is not None else np.nan for c in cases]
            se = [by[c]["coverage_se"] if c in by and by[c]["coverage_se"] is not None else 0.0 for c in cases]
            off = x - 0.4 + width * (k + 0.5)
            axes[0, col].bar(off, err, width, label=m, color=f"C{k}")
            axes[1, col].bar(off, cov, width, yerr=se, label=m, color=f"C{k}", capsize=2)
        for ax in axes[:, col]:
            ax.set_xticks(x, cases, rotation=45, ha="right", fontsize=8)
            ax.grid(True, axis="y", alpha=0.3)
        if shown:
            axes[0, col].set_yscale("log")
        axes[0, col].set_title(p)
        axes[0, col].set_ylabel("median relative error")
        axes[1, col].axhline(0.9, color="k", ls="--", lw=0.8)
        axes[1, col].set_ylim(0, 1.05)
        axes[1, col].set_ylabel("90 % interval coverage")
    half = ncol // 2
    panels = (
        (fig.add_subplot(grid[2, :half]), "mode frequency", "found", "modes found"),
        (fig.add_subplot(grid[2, half:]), "line frequency", "line_detection", "lines detected"),
    )
    for ax, p, key, title in panels:
        _detection_panel(ax, [r for r in rows if r["param"] == p], methods, key, width)
        ax.set_title(title)
    axes[0, 0].legend(fontsize=8)
    panels[1][0].legend(fontsize=8)
    fig.savefig(path, dpi=100, format="png")
    plt.close(fig)


def _detection_panel(ax, rows: list[dict], methods: list[str], key: str, width: float) -> None:
    """Bars of `key` per case and method, the oracle's rates as diamonds over each case."""
    cases = list(dict.fromkeys(r["case"] for r in rows))
    x = np.arange(len(cases))
    for k, m in enumerate(methods):
        by = {r["case"]: r for r in rows if r["method"] == m}
        val = [by[c].get(key) if c in by and by[c].get(key) is not None else np.nan for c in cases]
        ax.bar(x - 0.4 + width * (k + 0.5), val, width, label=m, color=f"C{k}")
    markers = (
        ("oracle_detection", "k", "oracle"),
        ("oracle_known_frequency", "none", "oracle, known frequency"),
        ("oracle_refit_detection", "0.6", "oracle, refitted"),
    )
    for dx, (name, face, label) in zip((-0.15, 0.0, 0.15), markers):  # side by side: none hides another
        first = {}
        for r in rows:
            first.setdefault(r["case"], r.get(name))
        val = [first[c] if first[c] is not None else np.nan for c in cases]
        ax.plot(x + dx, val, "D", mfc=face, mec="k", ms=7, ls="none", label=label)
    ax.set_xticks(x, cases, rotation=45, ha="right", fontsize=8)
    ax.set_ylim(0, 1.08)
    ax.axhline(0.95, color="k", ls=":", lw=0.8)
    ax.grid(True, axis="y", alpha=0.3)
    ax.set_ylabel("fraction of the true components")

"""The robustness bench's scene column (`vibinverse bench --robustness --scene`): the departures of
`robustness_cases` applied to data simulated from the scene `roof_frame.toml` (paper sec. 4.2: a
roof on a resonant frame, tilt resonance 2 sqrt 3 Hz, a 10 Hz drive line of 1 mm, white base
motion), fitted with that scene, as a user with a scene file fits.

Why a column of its own: the modal cases test the scene-less model on a generic oscillator; a scene
fit has its own likelihood (the frame's Kalman filter) and its own nuisance terms (AR(1) or 1/f
noise, random-walk drift, gain drift, chosen by a BIC search), which only data made by the forward
model exercise.

Data (`simulate`): `forward` simulates the scene with its sensor noise off (`noise.sigma = 0`) and
the case adds its own noise, drift, gain and gaps (reusing `robustness_cases`), so the departure is
exactly the case's. `forward` has neither jitter nor exposure, so the irregular and boxcar cases
are simulated on a grid FINE x finer and then sampled at jittered stamps or averaged over blocks.
The forward model holds the white base motion constant over each sample of its grid, so its
low-frequency power scales with the sample interval: a fine simulation scales
`surfaces.roof.motion.noise_rms` by sqrt(FINE) to keep the tilt resonance at its nominal amplitude.

Fitters: "ours-scene" (`vi.fit(series, scene)`, the nuisance terms chosen by BIC), "ours-scene-white"
(the white-noise frame model, no search: the behaviour before nuisance terms) and "ours" (the
scene-less modal model, `vi.fit(series)`: its tilt is the mode nearest 2 sqrt 3 Hz, its drive the
line nearest 10 Hz; its amplitudes are in intensity units, so only frequencies and damping are
compared). The analyst's scene is roof_frame.toml with `noise.sigma = 0.6`; the fit takes the
stamps from the data.

Metrics per case, fitter and parameter over N data sets (`score`): median relative error, 90 %
interval coverage with its binomial standard error, failures, seconds per fit, and for ours-scene
how often each set of nuisance terms was chosen.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import functools
import json
import logging
import math
import time
import zlib
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vibinverse.bench import robustness_cases as rc
from vibinverse.bench.robustness_fit import ModalFitter, failed_outcome, quiet
from vibinverse.errors import Interrupted

LOG = logging.getLogger(__name__).info

SCENE = "roof_frame.toml"
SURFACE = "roof"
FINE = rc.FINE  # irregular and boxcar data are simulated on a grid FINE x finer
SIGMA = 0.6  # the sensor noise sd of every case, and what the analyst's scene says
TILT_HZ = 2.0 * math.sqrt(3.0)  # where "ours" looks for the tilt mode
DRIVE_HZ = 10.0  # where "ours" looks for the drive line
QUICK_SETS = 1  # data sets per case with `quick` (see QUICK_CASES)
QUICK_CASES = ("clean", "gaps", "drift", "boxcar")  # the cases whose fits take seconds, not minutes
FITTERS = ("ours-scene", "ours-scene-white", "ours")

#: the compared parameters: name in the rows -> key of the truth and the outcome
PARAMS = {
    "tilt frequency": "tilt_frequency",
    "tilt damping": "tilt_damping_ratio",
    "drive frequency": "drive_frequency",
    "drive amplitude": "drive_amplitude",
}


# ------------------------------------------------------------------ the cases


@dataclass(frozen=True)
class SceneCase:
    """One departure from the clean scene simulation. `noise` "white", "ar1" (phi `ar_phi`) or "1/f"
    (OU processes of times `flicker_times`, equal variances), total sd `sigma`; `drift` the additive
    drift's peak to peak in units of the data set's noise-free signal sd; `gain` the largest |g| of
    the gain 1 + g(t) on the whole intensity; `jitter`, `drop` as `robustness_cases.Case`; `gaps`
    the fraction of samples NaN (runs of 5-40); `boxcar` each sample the mean of the intensity over
    its frame interval; `overrides` scene values of the simulation (e.g. the nonlinear model)."""

    name: str
    what: str
    noise: str = "white"
    sigma: float = SIGMA
    ar_phi: float = 0.9
    flicker_times: tuple[float, ...] = (0.01, 0.1, 1.0, 10.0)
    gaps: float = 0.0
    jitter: float = 0.0
    drop: float = 0.0
    drift: float = 0.0
    gain: float = 0.0
    boxcar: bool = False
    overrides: tuple[str, ...] = ()

    @property
    def fine(self) -> bool:
        """Whether the data need the FINE x finer simulation (jittered stamps or exposure)."""
        return self.boxcar or bool(self.jitter or self.drop)


_CLEAN = SceneCase("clean", "roof_frame.toml, white sensor noise sd 0.6")
SCENE_CASES: dict[str, SceneCase] = {
    c.name: c
    for c in (
        _CLEAN,
        dataclasses.replace(_CLEAN, name="gaps", what="clean + 10 % of the samples NaN, in runs of 5-40", gaps=0.10),
        dataclasses.replace(
            _CLEAN,
            name="irregular",
            what="clean on stamps jittered by up to 20 % of the interval (1/20 grid), 10 % frames dropped",
            jitter=0.20,
            drop=0.10,
        ),
        dataclasses.replace(
            _CLEAN, name="ar1", what="AR(1) sensor noise, phi 0.9, sd 0.6, no white noise", noise="ar1"
        ),
        dataclasses.replace(
            _CLEAN, name="one_over_f", what="1/f-like noise: 4 OU processes, times 0.01-10 s, total sd 0.6", noise="1/f"
        ),
        dataclasses.replace(
            _CLEAN, name="drift", what="clean + quadratic trend and random walk, 3x signal sd peak to peak", drift=3.0
        ),
        dataclasses.replace(
            _CLEAN, name="gain_drift", what="clean, whole intensity times 1 + g, max |g| 0.2", gain=0.2
        ),
        dataclasses.replace(
            _CLEAN, name="boxcar", what="clean, each sample the mean intensity over its frame interval", boxcar=True
        ),
        dataclasses.replace(
            _CLEAN,
            name="nonlinear",
            what="clean from the frame's nonlinear 6-DOF model (weak at these amplitudes)",
            overrides=(f'surfaces.{SURFACE}.motion.model="nonlinear"',),
        ),
    )
}


# ------------------------------------------------------------------ the simulator


@functools.cache
def _scene_table() -> dict[str, Any]:
    from forward.scene_file import read_table
    from vibinverse.io.builtin import builtin_scene

    return read_table(builtin_scene(SCENE))


def scene_table(overrides: Sequence[str] = ()) -> dict[str, Any]:
    """A copy of roof_frame.toml's table with `overrides` ("dotted.key=value") applied."""
    from forward.scene_file import apply_overrides

    return apply_overrides(copy.deepcopy(_scene_table()), list(overrides))


def analyst_scene() -> dict[str, Any]:
    """The scene every fit is given: roof_frame.toml with the sensor noise the analyst believes."""
    return scene_table([f"noise.sigma={SIGMA}"])


def scene_truth(table: dict[str, Any] | None = None) -> dict[str, float]:
    """The true tilt frequency and damping ratio (forward's modal form of the frame) and the drive
    line's frequency and amplitude of a scene table (default roof_frame.toml)."""
    from forward.scene_file import scene_from_table

    table = table if table is not None else scene_table()
    surface = next(s for s in scene_from_table(table).surfaces if s.name == SURFACE)
    f_tilt, zeta = surface.motion.params.modal()["tilt"]
    motion = table["surfaces"][SURFACE]["motion"]
    return {
        "tilt_frequency": float(f_tilt),
        "tilt_damping_ratio": float(zeta),
        "drive_frequency": float(motion["drive_frequency"][0]),
        "drive_amplitude": float(motion["drive_amplitude"][0]),
    }


def _rng(case: str, seed: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([int(seed), zlib.crc32(f"scene/{case}".encode())]))


def forward_signal(
    seed: int, fine: int = 1, overrides: Sequence[str] = (), duration: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(stamps, noise-free intensity) of roof_frame.toml simulated by `forward` on a grid `fine` x
    finer than the scene's, the base noise_rms scaled by sqrt(fine) so that the resonance keeps its
    nominal amplitude (module docstring)."""
    from forward.scene_file import scene_from_table
    from forward.sensor import observe

    base = scene_table(overrides)
    motion = base["surfaces"][SURFACE]["motion"]
    sets = ["noise.sigma=0"]
    if duration is not None:
        sets.append(f"sampling.duration={float(duration)!r}")
    if fine > 1:
        sets.append(f"sampling.fs={float(base['sampling']['fs']) * fine!r}")
        sets.append(f"surfaces.{SURFACE}.motion.noise_rms={float(motion['noise_rms']) * math.sqrt(fine)!r}")
    table = scene_table([*overrides, *sets])
    obs = observe(scene_from_table(table), int(seed))
    return np.asarray(obs.time, float), np.asarray(obs.intensity, float)


#: the sensor noise of a case by its kind, each of total sd `case.sigma`
NOISES: dict[str, Callable[[Any, np.ndarray, np.random.Generator], np.ndarray]] = {
    "white": lambda case, t, rng: case.sigma * rng.standard_normal(t.size),
    "ar1": lambda case, t, rng: rc.ar1(t.size, case.ar_phi, case.sigma, rng),
    "1/f": lambda case, t, rng: sum(
        rc.ou(t, tau, case.sigma / math.sqrt(len(case.flicker_times)), rng) for tau in case.flicker_times
    ),
}


def simulate_parts(
    case: SceneCase | str, seed: int, duration: float | None = None
) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, Any]]:
    """(stamps, parts, truth) of one seeded data set: parts "signal" (the scene's noise-free
    intensity at the stamps, exposure-averaged for boxcar), "gain" (g), "drift", "noise" and
    "gaps" (mask); intensity = (1 + g) signal + drift + noise, NaN at the gaps. `duration`
    shortens the record (tests)."""
    case = SCENE_CASES[case] if isinstance(case, str) else case
    rng = _rng(case.name, seed)
    fs = float(_scene_table()["sampling"]["fs"])
    span = float(duration if duration is not None else _scene_table()["sampling"]["duration"])
    fine = FINE if case.fine else 1
    t, signal = forward_signal(int(rng.integers(2**32)), fine, case.overrides, duration)
    if case.boxcar:  # a camera integrates over its frame interval: block means, stamped at the blocks' centres
        n = t.size // FINE
        t = t[: n * FINE].reshape(n, FINE).mean(axis=1)
        signal = signal[: n * FINE].reshape(n, FINE).mean(axis=1)
    elif case.fine:  # stamps on the fine grid, jittered and dropped as robustness_cases does
        grid = dataclasses.replace(rc.CASES["clean"], fs=fs, duration=span, jitter=case.jitter, drop=case.drop)
        idx = np.rint(rc.stamps(grid, rng) * fs * FINE).astype(np.int64)
        t, signal = t[idx], signal[idx]
    n = t.size
    parts = {"signal": signal, "gain": np.zeros(n), "drift": np.zeros(n)}
    signal_sd = float(np.std(signal))
    if case.gain:
        parts["gain"] = rc.gain(t, case.gain, rng)
    if case.drift:
        parts["drift"] = rc.drift(t, case.drift * signal_sd, rng)
    if case.noise not in NOISES:
        raise ValueError(f"noise: {case.noise!r}; allowed: {', '.join(NOISES)}")
    parts["noise"] = NOISES[case.noise](case, t, rng)
    parts["gaps"] = rc.gap_mask(n, case.gaps, rng) if case.gaps else np.zeros(n, bool)
    truth = {
        "case": case.name,
        "seed": int(seed),
        **scene_truth(scene_table(case.overrides)),
        "noise": case.noise,
        "sigma": case.sigma,
        "signal_sd": signal_sd,
        "n": int(n),
        "span": float(t[-1] - t[0]),
    }
    return t, parts, truth


def simulate(case: SceneCase | str, seed: int, duration: float | None = None) -> rc.Dataset:
    """One seeded data set of a scene case (`SCENE_CASES`): (time, intensity, truth)."""
    t, p, truth = simulate_parts(case, seed, duration)
    y = (1.0 + p["gain"]) * p["signal"] + p["drift"] + p["noise"]
    y[p["gaps"]] = np.nan
    return rc.Dataset(t, y, truth)


# ------------------------------------------------------------------ the fitters


@dataclass
class SceneOutcome:
    """What a fit reports on the compared parameters (`PARAMS`' keys): medians, 90 % intervals
    (q05, q95), the nuisance terms of the fitted model ("" for the modal fit), what formed the
    intervals, whether the sampler converged (None where there is no sampler), the wall time and
    whether it failed (with a note)."""

    values: dict[str, float] = field(default_factory=dict)
    intervals: dict[str, tuple[float, float]] = field(default_factory=dict)
    terms: str = ""
    posterior: str = ""
    converged: bool | None = None
    seconds: float = 0.0
    failed: bool = False
    note: str = ""


def _failed(t0: float, exc: BaseException) -> SceneOutcome:
    o = failed_outcome(t0, exc)
    return SceneOutcome(seconds=o.seconds, failed=True, note=o.note)


@dataclass
class SceneFitter:
    """Ours with the scene: `vi.fit(series, analyst_scene())`; `white` fixes the white-noise frame
    model (no nuisance search: the behaviour before nuisance terms)."""

    white: bool = False
    method: str = "auto"
    name: str = ""

    def __post_init__(self) -> None:
        self.name = self.name or ("ours-scene-white" if self.white else "ours-scene")

    def fit(self, t: np.ndarray, y: np.ndarray) -> SceneOutcome:
        import vibinverse as vi

        t0 = time.perf_counter()
        fixed = {"noise": "white", "drift": "none", "gain": False, "white": True} if self.white else {}
        try:
            with quiet():
                result = vi.fit(
                    vi.series(t, y, source="robustness scene bench"), analyst_scene(), method=self.method, **fixed
                )
            out = scene_outcome(result.summary())
        except Interrupted:  # SIGINT/SIGTERM stop the bench, not just this fit
            raise
        except Exception as exc:  # noqa: BLE001 - a failed fit is a result of the bench
            return _failed(t0, exc)
        out.seconds = time.perf_counter() - t0
        return out


def scene_outcome(summary: dict[str, Any]) -> SceneOutcome:
    """A SceneOutcome from a scene fit's summary: the roof's tilt and drive parameters, the model's
    nuisance terms ("white noise" when none was added), emcee where the summary names no
    approximation but has sampler diagnostics."""
    p = summary["parameters"]
    diag = summary.get("diagnostics") or {}
    model = (summary.get("data") or {}).get("model") or {}
    out = SceneOutcome(
        terms=str(model.get("terms") or "white noise"),
        posterior=str(summary.get("approximation") or ("emcee" if "n_steps" in diag else summary.get("method", ""))),
        converged=diag.get("converged"),
    )
    for key in PARAMS.values():
        entry = p.get(f"surfaces.{SURFACE}.motion.{key}")
        if entry is None:
            continue
        out.values[key] = float(entry["median"])
        if entry.get("q05") is not None and entry.get("q95") is not None:
            out.intervals[key] = (float(entry["q05"]), float(entry["q95"]))
    return out


@dataclass
class ModalSceneFitter:
    """Ours without the scene (`robustness_fit.ModalFitter`, order by BIC): the tilt is the mode
    nearest TILT_HZ, the drive the line nearest DRIVE_HZ (frequency only: its amplitude is in
    intensity units)."""

    method: str = "auto"
    name: str = "ours"

    def fit(self, t: np.ndarray, y: np.ndarray) -> SceneOutcome:
        o = ModalFitter(method=self.method).fit(t, y)
        if o.failed and o.note.startswith(f"{Interrupted.__name__}:"):  # ModalFitter records it as a failed fit
            raise Interrupted(o.note)
        out = SceneOutcome(posterior=o.posterior, seconds=o.seconds, failed=o.failed, note=o.note)
        if o.failed:
            return out
        picks = (  # (name prefix, frequencies, target, {field: (values, key)})
            ("modes", o.frequencies, TILT_HZ, {"frequency": (o.frequencies, "tilt_frequency")}),
            ("lines", o.line_frequencies, DRIVE_HZ, {"frequency": (o.line_frequencies, "drive_frequency")}),
        )
        for kind, freqs, target, fields in picks:
            if not freqs:
                continue
            i = int(np.argmin(np.abs(np.asarray(freqs) - target)))
            if kind == "modes":
                fields = {**fields, "damping_ratio": (o.damping_ratios, "tilt_damping_ratio")}
            for src, (values, key) in fields.items():
                out.values[key] = float(values[i])
                iv = o.intervals.get(f"{kind}[{i}].{src}")
                if iv is not None:
                    out.intervals[key] = (float(iv[0]), float(iv[1]))
        return out


def make_fitters(names: Sequence[str] | None = None, method: str = "auto") -> list:
    """The fitters by name (`FITTERS`; default all three), ours' posterior by `method`."""
    out = []
    for n in names if names is not None else FITTERS:
        if n == "ours-scene":
            out.append(SceneFitter(method=method))
        elif n == "ours-scene-white":
            out.append(SceneFitter(white=True, method=method))
        elif n == "ours":
            out.append(ModalSceneFitter(method=method))
        else:
            raise ValueError(f"fitter: {n!r}; allowed: {', '.join(FITTERS)}")
    return out


# ------------------------------------------------------------------ metrics


def _binomial(hits: list[bool]) -> tuple[float | None, float | None]:
    if not hits:
        return None, None
    p = float(np.mean(hits))
    return p, math.sqrt(p * (1.0 - p) / len(hits))


def score(case: str, method: str, truths: Sequence[dict], outcomes: Sequence[SceneOutcome]) -> list[dict]:
    """The rows of one case and fitter over its data sets: one per parameter the fitter reports in
    any data set, with the median relative and signed relative error, the 90 % coverage with its
    binomial standard error (over the fits with an interval), `n_missing` (fits that succeeded
    without a value: "ours" without a mode or line), failures, the mean seconds per fit, what
    formed the intervals and how often each set of nuisance terms was chosen."""
    good = [(tr, o) for tr, o in zip(truths, outcomes) if not o.failed]
    common = {
        "case": case,
        "method": method,
        "n": len(outcomes),
        "n_failed": len(outcomes) - len(good),
        "seconds": float(np.mean([o.seconds for o in outcomes])) if outcomes else None,
        "terms": dict(Counter(o.terms for _, o in good if o.terms).most_common()),
        "posterior": dict(Counter(o.posterior for _, o in good if o.posterior).most_common()),
        "not_converged": sum(o.converged is False for _, o in good),
    }
    rows = []
    for param, key in PARAMS.items():
        if not any(key in o.values for _, o in good) and good:
            continue
        errors, signed, covers = [], [], []
        for tr, o in good:
            if key not in o.values:
                continue
            true = tr[key]
            signed.append((o.values[key] - true) / abs(true))
            errors.append(abs(signed[-1]))
            iv = o.intervals.get(key)
            if iv is not None:
                covers.append(bool(iv[0] <= true <= iv[1]))
        cov, se = _binomial(covers)
        rows.append(
            {
                **common,
                "param": param,
                "n_missing": len(good) - len(errors),
                "median_rel_error": float(np.median(errors)) if errors else None,
                "median_signed_error": float(np.median(signed)) if signed else None,
                "coverage90": cov,
                "coverage_se": se,
                "n_intervals": len(covers),
            }
        )
    return rows


def rows_from_fits(
    fits: Iterable[dict], cases: Sequence[str] | None = None, methods: Sequence[str] | None = None
) -> list[dict]:
    """The rows (`score`) of fit records (`fit_record`), per case and method in the given order
    (default: as they first appear): also what scores a partial run's records file."""
    fits = list(fits)
    cases = list(cases) if cases is not None else list(dict.fromkeys(f["case"] for f in fits))
    methods = list(methods) if methods is not None else list(dict.fromkeys(f["method"] for f in fits))
    rows = []
    for c in cases:
        for m in methods:
            sel = [f for f in fits if f["case"] == c and f["method"] == m]
            if sel:
                outcomes = [_outcome(f["outcome"]) for f in sel]
                rows += score(c, m, [f["truth"] for f in sel], outcomes)
    return rows


def _outcome(d: dict | SceneOutcome) -> SceneOutcome:
    if isinstance(d, SceneOutcome):
        return d
    d = dict(d)
    d["intervals"] = {k: tuple(v) for k, v in (d.get("intervals") or {}).items()}
    return SceneOutcome(**d)


def fit_record(case: str, seed: int, method: str, truth: dict, outcome: SceneOutcome) -> dict:
    """One fit as JSON: case, seed, method, truth and the outcome's fields."""
    return {"case": case, "seed": int(seed), "method": method, "truth": truth, "outcome": dataclasses.asdict(outcome)}


def read_records(path: str | Path) -> list[dict]:
    """The fit records of a records file (one JSON list of records per line, one line per data set)."""
    out: list[dict] = []
    for line in Path(path).read_text().splitlines():
        if line.strip():
            out += json.loads(line)
    return out


# ------------------------------------------------------------------ the run


def _job(job: tuple) -> list[dict]:
    """One data set, every fitter: its fit records (a worker's unit of work)."""
    case, seed, names, method = job
    from threadpoolctl import threadpool_limits

    data = simulate(case, seed)
    out = []
    with threadpool_limits(1):
        for f in make_fitters(names, method):
            out.append(fit_record(case, seed, f.name, data.truth, f.fit(data.time, data.intensity)))
    return out


def run(
    quick: bool = False,
    n: int | None = None,
    cases: Sequence[str] | None = None,
    fitters: Sequence[str] | None = None,
    workers: int = 1,
    method: str = "auto",
    seed0: int = 0,
    log: Callable[[str], None] = LOG,
    records: str | Path | None = None,
) -> dict[str, Any]:
    """The scene column: `n` data sets per case (default 50; with `quick` QUICK_SETS of QUICK_CASES,
    whose fits take seconds: the AR(1) and 1/f searches take minutes a fit), each fitted by every
    fitter, `workers` processes over the data sets, the cases in the order given. `records`: a
    file to which each data set's fit records are appended as one JSON line as soon as it is done,
    so that an interrupted run keeps them (`read_records`, `rows_from_fits` score them). Returns
    {"rows", "fits", "notes", "settings", "seconds"}, JSON-able."""
    t_start = time.perf_counter()
    n = n if n is not None else (QUICK_SETS if quick else 50)
    cases = list(cases) if cases is not None else list(QUICK_CASES if quick else SCENE_CASES)
    for c in cases:
        if c not in SCENE_CASES:
            raise ValueError(f"case: {c!r}; allowed: {', '.join(SCENE_CASES)}")
    names = list(fitters) if fitters is not None else list(FITTERS)
    make_fitters(names)  # unknown names fail before any work
    jobs = [(c, seed0 + s, names, method) for c in cases for s in range(n)]
    fits: list[dict] = []
    rows: list[dict] = []
    with contextlib.ExitStack() as stack:
        if workers > 1 and len(jobs) > 1:
            import multiprocessing as mp
            from concurrent.futures import ProcessPoolExecutor

            pool = stack.enter_context(ProcessPoolExecutor(workers, mp_context=mp.get_context("fork")))
            results = pool.map(_job, jobs)
        else:
            results = map(_job, jobs)
        sink = stack.enter_context(open(records, "a")) if records is not None else None
        for c in cases:
            per: list[dict] = []
            for _ in range(n):
                recs = next(results)
                per += recs
                if sink is not None:
                    sink.write(json.dumps(recs) + "\n")
                    sink.flush()
            fits += per
            new = rows_from_fits(per, [c], names)
            rows += new
            for m in names:
                r = next((x for x in new if x["method"] == m), None)
                if r is not None:
                    log(f"  scene {c:<11} {m:<17} {r['n']:>3} sets, {r['seconds']:.1f} s/fit, {r['n_failed']} failed")
    notes = sorted({f"{f['method']} on {f['case']}: {f['outcome']['note']}" for f in fits if f["outcome"]["note"]})
    return {
        "rows": rows,
        "fits": fits,
        "notes": notes,
        "seconds": time.perf_counter() - t_start,
        "settings": {
            "scene": SCENE,
            "quick": quick,
            "n": n,
            "seeds": [seed0, seed0 + n - 1],
            "cases": {c: SCENE_CASES[c].what for c in cases},
            "truth": scene_truth(),
            "analyst_sigma": SIGMA,
            "fine": FINE,
            "methods": names,
            "method_ours": method,
            "workers": workers,
        },
    }


def table(result: dict[str, Any]) -> str:
    """The rows as a fixed-width text table: median relative error and median signed error (%),
    90 % coverage +- its standard error over n_iv intervals, missing values, failed fits over the
    data sets, seconds per fit; below it, per case, the nuisance terms ours-scene chose (count of
    data sets) and the notes."""
    fmt = lambda v, f: format("-", f">{f.split('.')[0]}") if v is None else format(v, f)
    pct = lambda v: None if v is None else 100.0 * v
    lines = [
        f"{'case':<12}{'method':<18}{'parameter':<17}{'med_err%':>9}{'bias%':>8}{'cover90':>8}{'+-se':>6}{'n_iv':>5}"
        f"{'missing':>8}{'failed':>8}{'s/fit':>8}"
    ]
    for r in result["rows"]:
        lines.append(
            f"{r['case']:<12}{r['method']:<18}{r['param']:<17}{fmt(pct(r['median_rel_error']), '9.2f')}"
            f"{fmt(pct(r['median_signed_error']), '8.2f')}{fmt(r['coverage90'], '8.2f')}{fmt(r['coverage_se'], '6.2f')}"
            f"{r['n_intervals']:>5}{r['n_missing']:>8}{r['n_failed']:>5}/{r['n']:<2}{fmt(r['seconds'], '8.1f')}"
        )
    seen = set()
    for r in result["rows"]:
        key = (r["case"], r["method"])
        if r["method"] == "ours-scene" and key not in seen:
            seen.add(key)
            terms = ", ".join(f"{k} {v}" for k, v in r["terms"].items()) or "-"
            lines.append(f"terms chosen by ours-scene on {r['case']}: {terms}")
    for r in result["rows"]:
        key = (r["case"], r["method"], "conv")
        if r.get("not_converged") and key not in seen:
            seen.add(key)
            lines.append(f"{r['method']} on {r['case']}: the sampler did not converge in {r['not_converged']} fits")
    lines += [f"note: {n}" for n in result.get("notes", [])]
    return "\n".join(lines)

"""`vibinverse bench --realdata [--quick]`: our tool on measured recordings with independent references.

Each case of the corpus (`realdata_cases`; CASES.md there) is run the way a user would run it:

- a video: `open_cube(path, fps=true_fps)` (the container's 50 fps is wrong, as a user told by the
  README would say with `--fps`), `detection_map(cube)`, whose lines of kind "vibration" are the
  claims; then, as the README's video walk-through does, the joint fit of the strongest claimed
  line's largest cluster (`vi.fit(cube, pixels=found.cluster(K), method="map")`), whose modes and
  lines that pass their detection test are claims too, with 90 % intervals. The video is read
  lazily, as `vibinverse detect` reads it;
- a series: read with `vi.load_series` (a channel by `value_column=`), then `vi.fit(series)` with
  the defaults.

Every detection and fit runs in its own process with a wall-clock limit (300 s, `--quick` 60 s; a
detection 3 x that): a run that does not answer in time is a result ("no answer within N s"),
never a hang. `workers` processes run at once.

Scoring per file and stage (`score`): a claim within a reference's tolerance of its apparent
frequency (folded into [0, fs/2]: aliasing) finds it; a claim that matches no reference, no
harmonic k f (k = 2..8), no sum or difference of two references, all folded, within the
tolerance widened to 2 Fourier bins of the record, is spurious; references marked not scored
(context) are never missed but explain claims. Interval coverage: the fraction of the claims that
match a reference (and have an interval) whose 90 % interval holds the reference's apparent
frequency. Wall time per step.
"""

from __future__ import annotations

import dataclasses
import itertools
import logging
import math
import os
import re
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from vibinverse.bench.limited_processes import Job, Step, StepResult, run_jobs
from vibinverse.bench.realdata_cases import (
    SERIES,
    VIDEO,
    Case,
    CaseFile,
    ChannelsInput,
    Reference,
    SeriesInput,
    load_cases,
    select,
)
from vibinverse.imaging.line_checks import VIBRATION

LOG = logging.getLogger(__name__)

FULL_LIMIT_S = 300.0  # wall-clock limit of one fit
QUICK_LIMIT_S = 60.0
DETECT_LIMIT_FACTOR = 3.0  # a detection map's limit, in fit limits
HARMONICS = tuple(range(2, 9))  # k f explains a claim, k = 2..8
EXPLAIN_BINS = 2.0  # a claim is explained within max(tolerance, 2 Fourier bins)
FIT_METHOD_CUBE = "map"  # the README's video walk-through: `fit CUBE --pixels detection.nc:K --method map`


# ------------------------------------------------------------------------------------------ scoring
def fold(f: float, fs: float | None) -> float:
    """The apparent frequency of a tone `f` sampled at `fs`: min over k of |f - k fs|, in [0, fs/2]
    (f itself when fs is not known)."""
    if not fs or not math.isfinite(fs):
        return abs(f)
    g = math.fmod(abs(f), fs)
    return min(g, fs - g)


@dataclass(frozen=True)
class Explainer:
    """What may explain a claim: a reference (`reference` set) or a harmonic, sum or difference of
    references, at its apparent frequency within `tolerance`; or a band of a reference."""

    label: str
    frequency: float
    tolerance: float
    reference: Reference | None = None
    band: tuple[float, float] | None = None

    def explains(self, f: float) -> bool:
        if self.band is not None:
            return self.band[0] <= f <= self.band[1]
        return abs(f - self.frequency) <= self.tolerance


def _tol(r: Reference, default: float) -> float:
    return r.tolerance_hz if r.tolerance_hz is not None else default


def explainers(refs: Sequence[Reference], fs: float | None, tolerance: float, floor: float = 0.0) -> list[Explainer]:
    """Every reference, its harmonics 2..8 and the sums and differences of two references, folded at
    `fs`, each within max(its tolerance (default `tolerance`), `floor`); references first."""
    out: list[Explainer] = []
    points = [r for r in refs if r.band_hz is None]
    for r in refs:
        if r.band_hz is not None:
            out.append(Explainer(r.name, r.value_hz, 0.0, r, r.band_hz))
        else:
            out.append(Explainer(r.name, fold(r.value_hz, fs), max(_tol(r, tolerance), floor), r))
    for r in points:
        for k in HARMONICS:
            out.append(Explainer(f"{k}x{r.value_hz:g}", fold(k * r.value_hz, fs), max(_tol(r, tolerance), floor)))
    for a, b in itertools.combinations(points, 2):
        t = max(_tol(a, tolerance), _tol(b, tolerance), floor)
        out.append(Explainer(f"{a.value_hz:g}+{b.value_hz:g}", fold(a.value_hz + b.value_hz, fs), t))
        if a.value_hz != b.value_hz:
            d = abs(a.value_hz - b.value_hz)
            out.append(Explainer(f"{max(a.value_hz, b.value_hz):g}-{min(a.value_hz, b.value_hz):g}", fold(d, fs), t))
    return out


@dataclass
class Claim:
    """A line or component that a stage reports: its (apparent) frequency, whether it is claimed as
    a detected vibration, its 90 % interval where it has one; after `score`, its verdict ("found",
    "context", "explained", "spurious", "not claimed"), what explains it, and whether its interval
    holds the reference it matches."""

    frequency: float
    stage: str
    what: str
    claimed: bool = True
    interval: tuple[float, float] | None = None
    kind: str = VIBRATION
    note: str = ""
    verdict: str = ""
    explained_by: str = ""
    reference_hz: float | None = None
    covered: bool | None = None


@dataclass
class Score:
    """One file's stage scored: the references found of those that count, the ones missed, the
    spurious claims, interval coverage (None: no matching claim has an interval)."""

    found: list[str] = field(default_factory=list)
    total: int = 0
    missed: list[str] = field(default_factory=list)
    spurious: list[float] = field(default_factory=list)
    n_covered: int = 0
    n_intervals: int = 0

    @property
    def coverage(self) -> float | None:
        return self.n_covered / self.n_intervals if self.n_intervals else None


def score(
    claims: Sequence[Claim],
    refs: Sequence[Reference],
    fs: float | None,
    tolerance: float,
    duration_s: float | None = None,
) -> Score:
    """Score `claims` (setting each one's verdict) against the references in the file (`refs`, the
    scored ones count as found or missed). `tolerance`: the file's, for references without their
    own; `duration_s`: the record's, whose 2 Fourier bins widen the tolerance of an explanation."""
    floor = EXPLAIN_BINS / duration_s if duration_s else 0.0
    direct = [(r, fold(r.value_hz, fs), _tol(r, tolerance)) for r in refs if r.band_hz is None]
    derived = explainers(refs, fs, tolerance, floor)
    out = Score()
    for c in claims:
        if not c.claimed:
            c.verdict = "not claimed"
            continue
        near = [(abs(c.frequency - f), r, f) for r, f, t in direct if abs(c.frequency - f) <= t]
        if near:
            _, r, f = min(near, key=lambda x: x[0])
            c.verdict, c.explained_by, c.reference_hz = ("found" if r.scored else "context"), r.name, f
            if c.interval is not None:
                c.covered = bool(c.interval[0] <= f <= c.interval[1])
                out.n_intervals += 1
                out.n_covered += int(c.covered)
            continue
        e = next((e for e in derived if e.explains(c.frequency)), None)
        if e is not None:
            c.verdict, c.explained_by = "explained", e.label
        else:
            c.verdict = "spurious"
            out.spurious.append(c.frequency)
    for r, f, t in direct:
        if not r.scored:
            continue
        out.total += 1
        hit = any(c.claimed and abs(c.frequency - f) <= t for c in claims)
        (out.found if hit else out.missed).append(f"{f:g}")
    return out


# ------------------------------------------------------------------------------- reading the series
def read_series(path: Path, spec: SeriesInput) -> tuple[Any, str]:
    """The channel `spec` names of `path` as a user reads it (`vi.load_series`, the channel by
    `value_column`), its first `spec.skip` samples dropped; how it was read."""
    import vibinverse as vi

    series = vi.load_series(path, time_column=spec.time_column, value_column=spec.channel)
    if spec.skip:
        series = dataclasses.replace(series, time=series.time[spec.skip :], intensity=series.intensity[spec.skip :])
    return series, "load_series"


# ------------------------------------------------------------------------------ what a fit claims
_COMPONENT = re.compile(r"^(modes|lines|decays)\[(\d+)\]\.frequency$")
_TEST = {"modes": "mode", "lines": "line", "decays": "decay"}  # the detection test's stem in the diagnostics


def claims_from_summary(summary: dict[str, Any], stage: str = "fit") -> list[Claim]:
    """Each mode and line of a modal fit's summary: its median frequency, 90 % interval, and claimed
    when it passed its detection test (`mode_{i}_detected`, `line_{j}_detected`; one without a test
    counts as claimed, as the robustness bench counts it)."""
    params = summary.get("parameters", {})
    diag = summary.get("diagnostics", {})
    out = []
    for name, p in params.items():
        m = _COMPONENT.match(name)
        if not m:
            continue
        test = f"{_TEST[m.group(1)]}_{m.group(2)}"
        lo, hi = p.get("q05"), p.get("q95")
        out.append(
            Claim(
                frequency=float(p["median"]),
                stage=stage,
                what=name.rsplit(".", 1)[0],
                claimed=diag.get(f"{test}_detected") is not False,
                interval=(float(lo), float(hi)) if lo is not None and hi is not None else None,
                kind=m.group(1)[:-1],
            )
        )
    return out


def claims_from_lines(lines: Sequence[Any]) -> list[Claim]:
    """A detection map's lines (`detection_map.Line`): claimed when `Line.claimed`."""
    out = []
    for line in lines:
        alias, note = line.alias_frequency, line.reason
        if math.isfinite(alias):
            note = f"{note}; other reading {alias:.4g} Hz".lstrip("; ")
        out.append(
            Claim(
                frequency=float(line.frequency),
                stage="detect",
                what=f"line {line.index} (SNR {line.snr:.3g}, {line.n_pixels} px)",
                claimed=line.claimed,
                kind=line.kind,
                note=note,
            )
        )
    return out


# ------------------------------------------------------------------------- the work of one process
def detect_video(path: str, fps: float) -> dict[str, Any]:
    """The detection map of a video at its true frame rate: its lines as claims, the record's
    length, and the mask of the strongest claimed line's largest cluster (None without one)."""
    from vibinverse.imaging.detection_map import detection_map
    from vibinverse.io.cube import open_cube

    cube = open_cube(path, fps=fps)
    n = int(cube.sizes["time"])
    found = detection_map(cube, workers=1)
    claims = claims_from_lines(found.lines)
    claimed = [line for line in found.lines if line.claimed]
    mask, cluster, pixels = None, None, 0
    if claimed:
        strongest = max(claimed, key=lambda line: line.snr)
        biggest = max(strongest.clusters, key=lambda c: c.n_pixels)
        cluster, pixels = int(biggest.cluster), int(biggest.n_pixels)
        mask = found.cluster(cluster)
    return {
        "claims": [dataclasses.asdict(c) for c in claims],
        "fs": float(fps),
        "duration_s": n / float(fps),
        "n_samples": n,
        "mask": mask,
        "cluster": cluster,
        "note": f"cluster {cluster} ({pixels} px) of the strongest claimed line" if cluster else "no claimed line",
    }


def fit_video(path: str, fps: float, mask: np.ndarray) -> dict[str, Any]:
    """The joint fit of the pixels `mask` of a video (the README's `fit CUBE --pixels detection.nc:K`)."""
    import vibinverse as vi
    from vibinverse.io.cube import open_cube

    cube = open_cube(path, fps=fps)
    n = int(cube.sizes["time"])
    result = vi.fit(cube, pixels=mask, method=FIT_METHOD_CUBE)
    return {
        "claims": [dataclasses.asdict(c) for c in claims_from_summary(result.summary())],
        "fs": float(fps),
        "duration_s": n / float(fps),
        "n_samples": n,
        "note": f"{int(mask.sum())} px, method {FIT_METHOD_CUBE}",
    }


def fit_series(path: str, spec: SeriesInput) -> dict[str, Any]:
    """The default fit (`vi.fit(series)`) of one channel of a series file."""
    import vibinverse as vi

    series, how = read_series(Path(path), spec)
    result = vi.fit(series)
    summary = result.summary()
    return {
        "claims": [dataclasses.asdict(c) for c in claims_from_summary(summary)],
        "fs": float(series.fs),
        "duration_s": float(series.time[-1] - series.time[0]),
        "n_samples": int(series.time.size),
        "note": f"{spec.channel}: {how}; {series.describe()}",
        "approximation": summary.get("approximation"),
    }


def fit_channels(path: str, spec: ChannelsInput) -> dict[str, Any]:
    """The modal identification of every response channel of a multi-channel file, as `vibinverse
    fit TABLE` runs it (`load_channels`, `vibinverse.oma.identify`): each mode a claim with its 90 %
    interval, unless it is a broad hump (`OmaMode.claimed`)."""
    from vibinverse.io.channels import Channels, load_channels
    from vibinverse.oma import identify

    ch = load_channels(path, channels=list(spec.channels) if spec.channels else None, inputs=spec.inputs)
    if spec.skip:
        ch = Channels(ch.time[spec.skip :], ch.values[spec.skip :], ch.names, ch.units, ch.source, inputs=ch.inputs)
    result = identify(ch, band=spec.band)
    claims = [
        Claim(m.frequency, "channels", f"modes[{i}]", m.claimed, tuple(m.frequency_interval), kind="mode")
        for i, m in enumerate(result.modes)
    ]
    return {
        "claims": [dataclasses.asdict(c) for c in claims],
        "fs": float(result.fs),
        "duration_s": float(ch.time[-1] - ch.time[0]),
        "n_samples": int(ch.time.size),
        "note": f"{', '.join(result.names)}: load_channels; {spec.note}",
        "approximation": result.method,
    }


# ------------------------------------------------------------------------------------ the runners
@dataclass(frozen=True)
class Settings:
    """A run's limits (s)."""

    fit_limit_s: float
    detect_limit_s: float


def _row(case: Case, file: CaseFile, stage: str, res: StepResult) -> dict:
    """One table row: a stage's result on a file, scored."""
    value = res.value or {}
    claims = [
        Claim(**{**c, "interval": tuple(c["interval"]) if c.get("interval") else None}) for c in value.get("claims", [])
    ]
    refs = [r for r in case.references if r.in_file(file.name)]
    fs = value.get("fs") or file.true_fps
    duration = value.get("duration_s") or file.duration_s
    tolerance = file.tolerance_hz if file.tolerance_hz is not None else (case.tolerance_hz or 0.0)
    s = score(claims, refs, fs, tolerance, duration)
    status = {"ok": "ok", "timeout": f"no answer within {res.seconds:.0f} s", "error": res.error}.get(res.status, "")
    return {
        "case": case.id,
        "file": file.label,
        "path": str(file.path),
        "stage": stage,
        "status": res.status,
        "status_text": status,
        "seconds": res.seconds,
        "fs": fs,
        "duration_s": duration,
        "tolerance_hz": tolerance,
        "found": s.found if res.status == "ok" else [],
        "n_found": len(s.found) if res.status == "ok" else None,
        "n_references": s.total,
        "missed": s.missed if res.status == "ok" else [],
        "spurious": s.spurious,
        "coverage": s.coverage,
        "n_covered": s.n_covered,
        "n_intervals": s.n_intervals,
        "claims": [dataclasses.asdict(c) for c in claims],
        "references": [{**dataclasses.asdict(r), "apparent_hz": fold(r.value_hz, fs)} for r in refs],
        "note": value.get("note", ""),
        # the case's expected failure is its single-series fit's (the plate: acceleration alone)
        "expected_failure": case.expected_failure if stage == "fit" else "",
    }


def _skipped(case: Case, file: CaseFile, stage: str, why: str) -> dict:
    row = _row(case, file, stage, StepResult("skipped", 0.0))
    row["status_text"] = why
    return row


class CaseRunner(Protocol):
    """Runs one file of a case as a job (`run_jobs`): yields its steps, returns its rows."""

    def job(self, case: Case, file: CaseFile, settings: Settings) -> Job: ...


class VideoRunner:
    """A video: the detection map, then the joint fit of the strongest claimed line's largest cluster."""

    def job(self, case: Case, file: CaseFile, settings: Settings) -> Job:
        path, fps = str(file.path), float(file.true_fps or 0.0)
        label = f"{case.id} {file.label}"
        det = yield Step("detect", detect_video, (path, fps), settings.detect_limit_s, label)
        rows = [_row(case, file, "detect", det)]
        mask = (det.value or {}).get("mask")
        if mask is None:
            rows.append(_skipped(case, file, "fit", "no claimed line to fit" if det.status == "ok" else "no detection"))
            return rows
        fit = yield Step("fit", fit_video, (path, fps, mask), settings.fit_limit_s, label)
        rows.append(_row(case, file, "fit", fit))
        return rows


class SeriesRunner:
    """A series: the default fit of the channel a user would fit."""

    def job(self, case: Case, file: CaseFile, settings: Settings) -> Job:
        if file.series is None:
            return [_skipped(case, file, "fit", "no channel given for this case (realdata_cases.SERIES_INPUTS)")]
        res = yield Step(
            "fit", fit_series, (str(file.path), file.series), settings.fit_limit_s, f"{case.id} {file.label}"
        )
        rows = [_row(case, file, "fit", res)]
        if file.channels is not None:  # and all its channels together: `vibinverse fit TABLE`
            res = yield Step(
                "channels",
                fit_channels,
                (str(file.path), file.channels),
                settings.fit_limit_s,
                f"{case.id} {file.label}",
            )
            rows.append(_row(case, file, "channels", res))
        return rows


#: a case's runner, by its kind
RUNNERS: dict[str, type[CaseRunner]] = {VIDEO: VideoRunner, SERIES: SeriesRunner}


def quick_files(case: Case) -> list[CaseFile]:
    """The files of a case in the quick form: a video case's take at the lowest frame rate (250 fps),
    a series case's first file."""
    if not case.files:
        return []
    rates = [f.true_fps for f in case.files if f.true_fps]
    if rates:
        return [min(case.files, key=lambda f: f.true_fps or math.inf)]
    return [case.files[0]]


def run(
    quick: bool = False,
    cases: list[str] | None = None,
    *,
    workers: int | None = None,
    limit_s: float | None = None,
    root: Path | None = None,
) -> dict[str, Any]:
    """Run the cases (`cases`: ids, default all) and score them. `quick`: the 250-fps take of each
    video, the first file of each series case, a 60 s fit limit (else 300 s; `limit_s` overrides).
    `workers`: processes at once (default min(2, cores)). Returns {"rows", "settings", "seconds"}."""
    t_start = time.perf_counter()
    chosen = select(load_cases(root), cases)
    fit_limit = float(limit_s) if limit_s is not None else (QUICK_LIMIT_S if quick else FULL_LIMIT_S)
    settings = Settings(fit_limit, DETECT_LIMIT_FACTOR * fit_limit)
    workers = workers if workers is not None else min(2, os.cpu_count() or 1)
    plan = [(c, f) for c in chosen for f in (quick_files(c) if quick else c.files)]
    jobs = [RUNNERS[c.kind]().job(c, f, settings) for c, f in plan]
    LOG.info(
        f"realdata: {len(plan)} file(s) of {len(chosen)} case(s), {workers} process(es), fit limit {fit_limit:g} s"
    )
    rows = [r for per in run_jobs(jobs, workers) for r in per]
    for r in rows:
        LOG.debug(f"{r['case']} {r['file']} {r['stage']}: {r['status_text']} ({r['seconds']:.1f} s)")
    return {
        "rows": rows,
        "settings": {
            "quick": quick,
            "cases": [c.id for c in chosen],
            "files": [str(f.path) for _, f in plan],
            "fit_limit_s": settings.fit_limit_s,
            "detect_limit_s": settings.detect_limit_s,
            "workers": workers,
            "video_fit_method": FIT_METHOD_CUBE,
            "harmonics": list(HARMONICS),
            "explain_bins": EXPLAIN_BINS,
        },
        "seconds": time.perf_counter() - t_start,
    }


# --------------------------------------------------------------------------------------- outputs
def _hz(values: Sequence[float], n: int = 6) -> str:
    shown = ", ".join(f"{v:.4g}" for v in values[:n])
    return shown + (f" +{len(values) - n}" if len(values) > n else "")


def _notes(r: dict[str, Any]) -> str:
    parts = [] if r["status"] == "ok" else [r["status_text"]]
    if r["status"] == "ok":
        claimed = [c for c in r["claims"] if c["claimed"]]
        parts.append(f"claims {_hz([c['frequency'] for c in claimed])}" if claimed else "no claim")
        if r["missed"]:
            parts.append(f"missed {', '.join(r['missed'])}")
        if r["spurious"]:
            parts.append(f"spurious {_hz(r['spurious'])}")
        others = [c for c in r["claims"] if not c["claimed"]]
        if others:
            parts.append(f"{len(others)} not claimed")
    if r.get("note"):
        parts.append(r["note"])
    if r.get("expected_failure"):
        parts.append(f"expected to fail: {r['expected_failure']}")
    return "; ".join(parts)


def table(result: dict[str, Any]) -> str:
    """One row per case, file and stage: references found / counted, spurious claims, interval
    coverage (covered / with an interval), seconds, notes."""
    head = f"{'case':<24} {'file':<28} {'stage':<6} {'found':>5} {'spur.':>5} {'cover':>7} {'s':>6}  notes"
    lines = [head, "-" * len(head)]
    for r in result["rows"]:
        ok = r["status"] == "ok"
        found = f"{r['n_found']}/{r['n_references']}" if ok else f"-/{r['n_references']}"
        spurious = str(len(r["spurious"])) if ok else "-"
        cover = f"{r['n_covered']}/{r['n_intervals']}" if ok and r["n_intervals"] else "-"
        lines.append(
            f"{r['case'][:24]:<24} {r['file'][:28]:<28} {r['stage']:<6} {found:>5} {spurious:>5} {cover:>7} "
            f"{r['seconds']:>6.1f}  {_notes(r)}"
        )
    s = result.get("settings", {})
    lines.append(
        f"{len(result['rows'])} rows in {result.get('seconds', 0.0):.0f} s; fit limit {s.get('fit_limit_s', 0):g} s, "
        f"detection limit {s.get('detect_limit_s', 0):g} s"
    )
    return "\n".join(lines)


#: marker and colour of a claim by verdict
STYLES = {
    "found": ("o", "tab:green"),
    "context": ("o", "tab:blue"),
    "explained": ("s", "tab:blue"),
    "spurious": ("x", "tab:red"),
    "not claimed": ("o", "0.6"),
}


def plot(result: dict[str, Any], path: str | Path) -> None:
    """Per row (case, file, stage) the references (black: scored, grey: context) and the claims on a
    log-frequency axis: found green, explained or context blue, spurious red, not claimed grey; fit
    intervals as bars; a row without an answer says why."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    rows = result["rows"]
    fig, ax = plt.subplots(figsize=(11, 1.0 + 0.42 * max(1, len(rows))))
    freqs = [c["frequency"] for r in rows for c in r["claims"]] + [
        x["apparent_hz"] for r in rows for x in r["references"]
    ]
    freqs = [f for f in freqs if f > 0]
    lo, hi = (min(freqs) / 1.5, max(freqs) * 1.5) if freqs else (1.0, 1000.0)
    for y, r in enumerate(rows):
        for ref in r["references"]:
            if ref.get("band_hz"):
                ax.plot(ref["band_hz"], [y, y], color="0.7", lw=4, alpha=0.5)
            else:
                ax.plot([ref["apparent_hz"]] * 2, [y - 0.35, y + 0.35], color="k" if ref["scored"] else "0.6", lw=1.5)
        for c in r["claims"]:
            marker, colour = STYLES.get(c["verdict"], ("o", "0.6"))
            if c.get("interval"):
                ax.plot(c["interval"], [y + 0.12] * 2, color=colour, lw=2)
            face = "none" if c["verdict"] == "not claimed" else colour
            ax.plot([c["frequency"]], [y + 0.12], marker=marker, ms=6, ls="", color=colour, mfc=face, zorder=3)
        if r["status"] != "ok":
            ax.text(lo * 1.05, y, r["status_text"][:60], va="center", fontsize=7, color="tab:red")
    ax.set_xscale("log")
    ax.set_xlim(lo, hi)
    ax.set_ylim(len(rows) - 0.5, -0.5)
    ax.set_yticks(range(len(rows)))
    ax.set_yticklabels([f"{r['case'][:22]} {r['file'][:14]} {r['stage']}" for r in rows], fontsize=7)
    ax.set_xlabel("apparent frequency (Hz)")
    ax.grid(True, axis="x", which="both", alpha=0.3)
    handles = [Line2D([], [], color="k", label="reference"), Line2D([], [], color="0.6", label="context")]
    handles += [
        Line2D([], [], marker=m, color=c, ls="", label=v, markerfacecolor="none" if v == "not claimed" else c)
        for v, (m, c) in STYLES.items()
    ]
    ax.legend(handles=handles, fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    ax.set_title(f"vibinverse on real data ({'quick' if result.get('settings', {}).get('quick') else 'full'})")
    fig.tight_layout()
    fig.savefig(path, dpi=110, format="png")  # `write_all` writes to a temporary name first
    plt.close(fig)

"""The real-data corpus of `vibinverse bench --realdata`: `cases.json` read into small dataclasses.

The corpus (`realdata-dev`, see its CASES.md) holds measured recordings with references that do
not come from vibinverse. Where it lives: the `VIBINVERSE_REALDATA` environment variable, else
`<repo>/../shared/realdata-dev` (repo: the directory holding pyproject.toml above this file).

What cases.json does not say is kept here, as data:

- `SERIES_INPUTS`: per series case, the channel a user would fit (the column or
  array name), a time column, and samples to drop at the start;
- `CHANNEL_INPUTS`: per multi-channel case, how its channels are fitted together (measured inputs,
  samples to drop, the band searched);
- `EXTRA_CONTEXT`: frequencies that CASES.md names as seen in the data but not as references
  (the footbridge's 17.5 Hz secondary peak, the slab's 17.0 Hz peak, ...). Like the references
  marked `"check": false`, they are not scored (never missed) but explain a claim.

A reference's tolerance is its own `tolerance_hz`, else the case's; the forks' case tolerance is
the rule "max(2/T, 0.5 % of f)" (T the take's true duration), evaluated per file.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from vibinverse.errors import InputError

ENV = "VIBINVERSE_REALDATA"
CASES_FILE = "cases.json"
VIDEO = "video"  # the case kinds: a video (image cube) or a measured series
SERIES = "series"


@dataclass(frozen=True)
class Reference:
    """One reference frequency of a case (Hz, true, before any aliasing) with its tolerance;
    `scored` False for context (never missed, explains claims); `present_in` the files (base
    names) it is in, None for every file; `band_hz` a band that explains any claim inside it."""

    name: str
    value_hz: float
    kind: str
    tolerance_hz: float | None  # None: the file's tolerance
    scored: bool = True
    present_in: tuple[str, ...] | None = None
    band_hz: tuple[float, float] | None = None
    source: str = ""

    def in_file(self, name: str) -> bool:
        """Whether the reference is in the file of base name `name`."""
        return self.present_in is None or name in self.present_in


@dataclass(frozen=True)
class SeriesInput:
    """How a user reads one channel of a series file (`vi.load_series`): the column, array or lvm
    channel (`channel`, by name or 0-based index), the time column (None: the format's own), the
    leading samples to drop, and a note on the choice."""

    channel: str
    time_column: str | None = None
    skip: int = 0
    note: str = ""


@dataclass(frozen=True)
class CaseFile:
    """One recording of a case: its path, the true sampling rate where the case states one (the
    videos' true fps), the expected apparent frequency and tolerance (None: per reference)."""

    path: Path
    true_fps: float | None = None
    expected_apparent_hz: float | None = None
    aliased: bool = False
    duration_s: float | None = None
    tolerance_hz: float | None = None
    series: SeriesInput | None = None
    channels: ChannelsInput | None = None
    label: str = ""  # short name in tables: its folder when that tells the case's files apart, else its stem

    @property
    def name(self) -> str:
        return self.path.name


@dataclass(frozen=True)
class Case:
    """A case: id, kind (VIDEO or SERIES), its files, references, the case tolerance (Hz; None:
    a rule evaluated per file) and CASES.md's notes."""

    id: str
    kind: str
    files: tuple[CaseFile, ...]
    references: tuple[Reference, ...]
    tolerance_hz: float | None
    notes: str = ""
    expected_failure: str = ""  # why a single-series fit is not expected to find the references ("" when it is)

    def scored(self, file: CaseFile) -> list[Reference]:
        """The references that count for `file` (found or missed)."""
        return [r for r in self.references if r.scored and r.in_file(file.name)]


#: per series case: how a user reads it (cases.json gives formats in prose only)
SERIES_INPUTS: dict[str, SeriesInput] = {
    "ligo_h1_gw150914_lines": SeriesInput("strain", note="strain, fs from the scalar 'fs'"),
    "beam_shaker_drive_tones": SeriesInput(
        "2",
        note="acceleration [g] (channel 2: set 1 names it 'Acceleratio', set 3 'Acceleration'); time from the "
        "X_Value column (the header's rate is wrong)",
    ),
    "plate_sweep_force_acc": SeriesInput("acc", note="acceleration only: the reference needs force + acc"),
    "slab_smartphone_walking": SeriesInput(
        "Z-Axis (m/s2)", time_column="Time (s)", skip=2000, note="Z, first 2000 samples dropped"
    ),
    "footbridge_impulse_3ch": SeriesInput("Acceleration_0", note="Acceleration_0 [g]"),
}


@dataclass(frozen=True)
class ChannelsInput:
    """How a user reads a multi-channel file (`load_channels`) for `vibinverse fit TABLE`: the
    channels that are measured inputs, the leading samples to drop, the band searched (None: all),
    a note, and the channels read (None: all)."""

    inputs: tuple[str, ...] = ()
    skip: int = 0
    band: tuple[float, float] | None = None
    note: str = ""
    channels: tuple[str, ...] | None = None  # the channels read (None: all)


#: per multi-channel case, the modal identification of all its response channels (`fit TABLE`)
CHANNEL_INPUTS: dict[str, ChannelsInput] = {
    "footbridge_impulse_3ch": ChannelsInput(band=(5.0, 100.0), note="3 accelerometers, 5-100 Hz"),
    "slab_smartphone_walking": ChannelsInput(skip=2000, note="X, Y, Z, first 2000 samples dropped"),
    "plate_sweep_force_acc": ChannelsInput(
        inputs=("force",), channels=("force", "acc"), band=(50.0, 600.0), note="acc given the measured force"
    ),
}


#: cases whose references the tool is not expected to reach from the channel it is given
EXPECTED_FAILURES: dict[str, str] = {
    "plate_sweep_force_acc": "a swept sine: acceleration alone shows the sweep envelope; the FRF peaks need force+acc",
}

#: context named in CASES.md but not in cases.json's references: (case, name, Hz, tolerance, band, files)
EXTRA_CONTEXT: tuple[tuple[str, str, float, float | None, tuple[float, float] | None, tuple[str, ...] | None], ...] = (
    ("footbridge_impulse_3ch", "secondary peak ~17.5 Hz (CASES.md)", 17.5, 0.5, None, None),
    ("footbridge_impulse_3ch", "peak ~59 Hz (CASES.md, mains?)", 59.0, 0.5, None, None),
    ("footbridge_impulse_3ch", "peaks 29-36 Hz (CASES.md)", 32.5, None, (29.0, 36.0), None),
    ("slab_smartphone_walking", "second peak ~17.0 Hz (CASES.md)", 17.0, 0.25, None, None),
    (
        "tuningfork_128hz_video",
        "unexplained ~122.1 Hz component (CASES.md)",
        122.1,
        None,
        None,
        ("tuning_hz128_fps500_50-1_640x420.mp4",),
    ),
)


def repo_root(start: Path | None = None) -> Path | None:
    """The directory holding pyproject.toml at or above `start` (default: this file)."""
    here = (start or Path(__file__)).resolve()
    for d in (here, *here.parents):
        if (d / "pyproject.toml").is_file():
            return d
    return None


def corpus_dir() -> Path:
    """The corpus: $VIBINVERSE_REALDATA, else <repo>/../shared/realdata-dev; a one-line InputError
    naming the path and the variable when it has no cases.json."""
    env = os.environ.get(ENV)
    if env:
        path = Path(env).expanduser()
    else:
        root = repo_root()
        path = (root.parent if root is not None else Path.cwd()) / "shared" / "realdata-dev"
    if not (path / CASES_FILE).is_file():
        raise InputError(f"realdata corpus: no {CASES_FILE} in {path}; set {ENV} to the corpus directory")
    return path


def _number(v: Any) -> float | None:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else None


def _references(case: dict[str, Any]) -> list[Reference]:
    refs = []
    for r in case.get("reference", []):
        values = [r["value_hz"]] if _number(r.get("value_hz")) is not None else list(r.get("values_hz") or [])
        present = r.get("present_in")
        for v in values:  # value_hz null and no values_hz (a non-stationarity): not a frequency
            refs.append(
                Reference(
                    name=str(r.get("name", "")),
                    value_hz=float(v),
                    kind=str(r.get("kind", "")),
                    tolerance_hz=_number(r.get("tolerance_hz")),
                    scored=r.get("check") is not False and r.get("kind") != "context",
                    present_in=tuple(present) if isinstance(present, dict) else None,
                    source=str(r.get("source", "")),
                )
            )
    for cid, name, value, tol, band, files in EXTRA_CONTEXT:
        if cid == case["id"]:
            refs.append(Reference(name, value, "context", tol, scored=False, present_in=files, band_hz=band))
    return refs


def _files(case: dict[str, Any], root: Path, kind: str, tolerance: float | None) -> list[CaseFile]:
    files = []
    for f in case.get("files", []):
        is_video = f.get("kind") == VIDEO
        if is_video != (kind == VIDEO):  # a video case's ffprobe JSON and ROI files are not inputs
            continue
        duration = _number(f.get("duration_true_s"))
        expected = _number(f.get("expected_apparent_hz"))
        tol = tolerance
        if tol is None and duration and expected:  # the forks' rule: max(2/T, 0.5 % of f)
            tol = max(2.0 / duration, 0.005 * expected)
        files.append(
            CaseFile(
                path=root / f["path"],
                true_fps=_number(f.get("true_fps")),
                expected_apparent_hz=expected,
                aliased=bool(f.get("aliased", False)),
                duration_s=duration,
                tolerance_hz=tol,
                series=SERIES_INPUTS.get(case["id"]) if kind == SERIES else None,
                channels=CHANNEL_INPUTS.get(case["id"]) if kind == SERIES else None,
            )
        )
    parents = [f.path.parent.name for f in files]
    distinct = len(set(parents)) == len(parents) > 1
    return [replace(f, label=f.path.parent.name if distinct else f.path.stem) for f in files]


def load_cases(root: Path | None = None) -> list[Case]:
    """Every case of `root`/cases.json (default: `corpus_dir()`), in its order."""
    root = corpus_dir() if root is None else Path(root)
    path = root / CASES_FILE
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InputError(f"realdata corpus: cannot read {path}: {exc}") from None
    cases = []
    for c in doc.get("cases", []):
        kind = VIDEO if any(f.get("kind") == VIDEO for f in c.get("files", [])) else SERIES
        tolerance = _number(c.get("tolerance_hz"))
        cases.append(
            Case(
                id=str(c["id"]),
                kind=kind,
                files=tuple(_files(c, root, kind, tolerance)),
                references=tuple(_references(c)),
                tolerance_hz=tolerance,
                notes=str(c.get("notes", "")),
                expected_failure=EXPECTED_FAILURES.get(str(c["id"]), ""),
            )
        )
    return cases


def select(cases: list[Case], ids: list[str] | None) -> list[Case]:
    """`cases` restricted to `ids` in that order (None: all); an InputError naming an unknown id."""
    if ids is None:
        return list(cases)
    by_id = {c.id: c for c in cases}
    for i in ids:
        if i not in by_id:
            raise InputError(f"--cases: {i!r}; allowed: {', '.join(by_id)}")
    return [by_id[i] for i in ids]

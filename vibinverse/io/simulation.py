"""The simulated-series CSV (time,intensity,intensity_clean) and its quick-look plot."""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path
from typing import Any

import numpy as np

from forward.sensor import Observation


def write_series_csv(path: Path, obs: Observation, table: dict[str, Any], seed: int | None, version: str) -> None:
    """CSV with '#' comment lines carrying the scene (the true values), the seed and the sensitivity.

    The title and the scene are JSON-encoded, so each comment line stays one line whatever their
    strings hold (a line break in the title cannot start a data row). TOML dates and times become
    ISO 8601 text (what `sun.date` also accepts). Values are written with 17 significant digits:
    the vibration signal is often 1e-6 of the mean.
    """
    header = [
        f"vibinverse {version} simulate",
        "title: " + json_line(table.get("title", "")),
        f"seed: {None if seed is None else int(seed)}",
        f"sensitivity: {obs.sensitivity:.6e}",
        "scene: " + json.dumps(table, separators=(",", ":"), default=_jsonable),
    ]
    data = np.column_stack([obs.time, obs.intensity, obs.intensity_clean])
    with open(path, "w", encoding="utf-8") as fh:
        fh.writelines(f"# {line}\n" for line in header)
        fh.write("time,intensity,intensity_clean\n")
        np.savetxt(fh, data, delimiter=",", fmt="%.17g")


def json_line(value: Any) -> str:
    """`value` as JSON on one line, readable: non-ASCII text stays as it is, but every character that
    is not printable (line and paragraph separators, controls, lone surrogates) is escaped."""
    text = json.dumps(value, ensure_ascii=False, default=_jsonable)
    return text if text.isprintable() else "".join(c if c.isprintable() else _escape(c) for c in text)


def _escape(c: str) -> str:
    o = ord(c)
    if o > 0xFFFF:  # JSON escapes beyond the BMP as a UTF-16 surrogate pair
        o -= 0x10000
        return f"\\u{0xD800 + (o >> 10):04x}\\u{0xDC00 + (o & 0x3FF):04x}"
    return f"\\u{o:04x}"


def _jsonable(obj: Any) -> Any:
    """JSON for what a scene table may hold beyond JSON: TOML dates and times, numpy values."""
    if isinstance(obj, (dt.date, dt.time)):  # datetime is a date
        return obj.isoformat()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    return str(obj)


def plot_series(path: Path, obs: Observation, title: str) -> None:
    """Two panels: the series (measured and clean) and the amplitude spectrum of the clean AC part."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(8, 6), constrained_layout=True)
    ax1.plot(obs.time, obs.intensity, lw=0.6, color="0.6", label="measured")
    ax1.plot(obs.time, obs.intensity_clean, lw=1.0, color="C0", label="clean")
    ax1.set(
        xlabel="time (s)",
        ylabel="x(t) (1/sr per unit irradiance)",
        title=f"{title}\nsensitivity S = {obs.sensitivity:.3e} (eq. 21)",
    )
    ax1.legend(loc="upper right")
    ac = obs.intensity_clean - obs.intensity_clean.mean()
    fs = 1.0 / np.median(np.diff(obs.time))
    freq = np.fft.rfftfreq(ac.size, 1.0 / fs)
    amp = 2.0 * np.abs(np.fft.rfft(ac)) / ac.size
    ax2.semilogy(freq[1:], np.maximum(amp[1:], 1e-300), color="C0")
    ax2.set(xlabel="frequency (Hz)", ylabel="amplitude of the clean AC part")
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)

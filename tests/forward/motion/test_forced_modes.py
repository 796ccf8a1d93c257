"""Modes driven by a measured band-limited force (forward.motion.forced_modes)."""

import math

import numpy as np
import pytest
from scipy import signal

from forward.errors import SceneError
from forward.motion.forced_modes import forced_modes

MODES = ((12.0, 0.02), (31.0, 0.015))
RESIDUES = np.array([[1.0, -0.5], [0.4, 0.8]])


def test_sampled_records_obey_y_equals_h_times_force():
    """Oracle: H1 = S_py / S_pp of the sampled records is the continuous-time receptance sum (no
    sensor noise), to Welch's own leakage (relative to the modes' summed magnitudes, which an
    antiresonance's cancellation does not shrink)."""
    fs = 200.0
    t, p, y = forced_modes(MODES, RESIDUES, fs=fs, duration=200.0, noise=0.0, seed=3)
    assert t.size == p.size == y.shape[0] == 40000 and y.shape[1] == 2
    f, spp = signal.welch(p, fs=fs, nperseg=4000)
    _, spy = signal.csd(p[:, None], y, fs=fs, nperseg=4000, axis=0)
    band = (f > 3.0) & (f < 60.0)
    w = 2 * math.pi * f[band]
    parts = [
        np.outer(1.0 / ((2 * math.pi * fm) ** 2 - w**2 + 2j * z * 2 * math.pi * fm * w), a)
        for (fm, z), a in zip(MODES, RESIDUES, strict=True)
    ]
    error = np.abs(spy[band] / spp[band, None] - sum(parts)) / sum(np.abs(q) for q in parts)
    assert np.median(error) < 0.005 and np.quantile(error, 0.95) < 0.02


def test_force_is_band_limited_below_cutoff():
    fs = 200.0
    _, p, _ = forced_modes(MODES, RESIDUES, fs=fs, duration=100.0, seed=1)
    f, spp = signal.welch(p, fs=fs, nperseg=2000)
    assert np.median(spp[f > 0.45 * fs]) < 1e-4 * np.median(spp[(f > 5) & (f < 0.3 * fs)])


@pytest.mark.parametrize(
    ("kwargs", "word"),
    [
        ({"modes": ((120.0, 0.02),)}, "modes"),
        ({"modes": ((12.0, 0.0),)}, "modes"),
        ({"cutoff": 0.6}, "cutoff"),
        ({"residues": np.ones((3, 2))}, "residues"),
    ],
)
def test_bad_arguments_are_refused_in_one_line(kwargs, word):
    args = {"modes": MODES, "residues": RESIDUES, **kwargs}
    if "residues" not in kwargs and len(args["modes"]) == 1:
        args["residues"] = RESIDUES[:1]
    with pytest.raises(SceneError) as e:
        forced_modes(args["modes"], args["residues"], fs=200.0, duration=10.0, cutoff=args.get("cutoff", 0.4))
    assert str(e.value).startswith(word) and "\n" not in str(e.value)

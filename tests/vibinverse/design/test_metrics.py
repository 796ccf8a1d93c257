"""What a configuration buys: the design's Cramer-Rao bounds against the sinusoid bound, the spread
of least-squares estimates and the inverse core's numbers; noise is required."""

import math

import numpy as np
import pytest

from forward.scene_file import scene_from_table
from tests.conftest import K, table
from vibinverse.design.metrics import line_amplitude
from vibinverse.design.spec import configure
from vibinverse.design.sweep import run_design


def test_deterministic_crlb_equals_the_sinusoid_bound():
    """Rife & Boorstyn (1974): a real sinusoid of amplitude A in white noise sigma, N samples at fs,
    phase and level unknown: sd(f) = sqrt(24 sigma^2 / (A^2 N (N^2 - 1))) fs / (2 pi)."""
    base = table("roof_elastic", "footprint.resolution=64")
    res = run_design(base, ["sensor.offset=0.015"], [K + "frequency"])
    r = res["rows"][0]
    from forward.reduce import compile_scene

    scene = scene_from_table(configure(base, {"sensor.offset": 0.015}))
    c = compile_scene(scene, force="taylor2")
    amp = line_amplitude(c.t, c.parts()[1], 40.0)
    n, fs, sigma = c.t.size, scene.sampling.fs, scene.noise.sigma
    bound = math.sqrt(24 * sigma**2 / (amp**2 * n * (n**2 - 1))) * fs / (2 * math.pi)
    assert r[f"crlb {K}frequency"] == pytest.approx(bound, rel=0.01)  # the 2f line adds < 1e-4


def test_crlb_matches_the_spread_of_least_squares_estimates():
    """50 simulated datasets fitted by least squares on the forward model: the empirical sd of the
    frequency estimate matches the design's Cramer-Rao sd (the estimator is efficient at this SNR).
    With 50 datasets the sample sd itself scatters by ~10 %, so 30 % is a 3-sigma band."""
    from scipy.optimize import least_squares

    from forward.reduce import compile_scene
    from forward.sensor import add_noise

    base = table("roof_elastic", "footprint.resolution=32", "sampling.duration=0.2", "noise.sigma=0.5")
    freq, defl = K + "frequency", K + "center_deflection"
    crlb = run_design(base, ["sensor.offset=0.01"], [freq, defl])["rows"][0][f"crlb {freq}"]
    scene0 = scene_from_table(configure(base, {"sensor.offset": 0.01}))
    cache: dict = {}

    def model(p):
        tab = configure(
            base, {"sensor.offset": 0.01, freq: p[0], defl: p[1] * 1e-3, "surfaces.roof.motion.phase": p[2]}
        )
        dc, ac = compile_scene(scene_from_table(tab), force="taylor2", shape_cache=cache).parts()
        return dc + p[3] + ac

    clean = model([40.0, 1.0, 0.0, 0.0])
    estimates = []
    for seed in range(50):
        y = add_noise(clean, scene0.noise, np.random.default_rng(seed))
        fit = least_squares(lambda p: model(p) - y, [40.0, 1.0, 0.0, 0.0], x_scale=[0.01, 0.01, 0.01, 0.01])
        estimates.append(fit.x[0])
    spread = float(np.std(estimates, ddof=1))
    assert spread == pytest.approx(crlb, rel=0.3)
    assert abs(np.mean(estimates) - 40.0) < 3 * crlb / math.sqrt(50) + 1e-9


def test_frame_design_reproduces_the_inverse_cores_numbers():
    res = run_design(table("roof_frame", "noise.sigma=0.6"), ["sensor.offset=0.01"], None)
    r = res["rows"][0]
    assert r["snr 10 Hz"] == pytest.approx(11.0, rel=0.05)  # the demo's "SNR ~10" setting
    assert r[f"crlb {K}drive_frequency"] == pytest.approx(0.00251, rel=0.02)  # issue 6's CRB
    assert 0 < r[f"crlb {K}tilt_frequency"] < 0.1 and r[f"crlb {K}tilt_damping_ratio"] > 0


def test_design_needs_noise():
    res = run_design(table("ground_rayleigh"), ["sun.inclination=0.1"], None)
    assert "design needs sensor noise" in res["rows"][0]["status"]

"""Sensor noise: seeded, with the stated statistics; shot noise and the ADC."""

import numpy as np
import pytest

from forward.errors import SceneError
from forward.reduce import compile_scene
from forward.render import pixel_signal
from forward.sensor import observe
from tests.conftest import FAST, LOW_RES


def test_noise_is_reproducible_and_has_the_stated_statistics(scene):
    s = scene("roof_elastic", *FAST, "noise.sigma=0.5")
    a, b, c = observe(s, seed=3), observe(s, seed=3), observe(s, seed=4)
    np.testing.assert_array_equal(a.intensity, b.intensity)
    assert not np.array_equal(a.intensity, c.intensity)
    resid = a.intensity - a.intensity_clean
    assert resid.std() == pytest.approx(0.5, rel=4 / np.sqrt(resid.size))


def test_shot_noise_variance_is_mean_over_gain_and_adc_quantizes(scene):
    s = scene("roof_elastic", *FAST, "noise.sigma=0", "noise.photons_per_unit=100", "sampling.duration=0.5")
    o = observe(s, seed=1)
    resid = o.intensity - o.intensity_clean
    assert resid.var() == pytest.approx(o.intensity_clean.mean() / 100, rel=0.15)
    q = observe(scene("roof_elastic", *FAST, "noise.sigma=0", "noise.adc_bits=8", "noise.adc_full_scale=255"), seed=1)
    np.testing.assert_allclose(q.intensity, np.round(q.intensity))


# ------------------------------------------------------------------ no traceback, no wrong series


def _one_line(err) -> str:
    message = str(err.value)
    assert message and "\n" not in message and len(message) < 500, message
    return message


@pytest.mark.parametrize("seed", [-1, 2**32, 2**64, 1.5, True, "3"])
def test_seeds_outside_32_bits_are_refused_in_one_line(scene, seed):
    s = scene("roof_frame", "sampling.duration=1")
    for run in (lambda: observe(s, seed=seed), lambda: pixel_signal(s, seed=seed), lambda: compile_scene(s, seed=seed)):
        with pytest.raises(SceneError, match=r"seed: .*allowed range \[0, 2\^32\)") as err:
            run()
        _one_line(err)


def test_seeds_at_the_ends_of_the_range_work(scene):
    s = scene("roof_frame", "sampling.duration=1")
    for seed in (0, 2**32 - 1, np.uint32(7), np.int64(7), None):
        assert np.all(np.isfinite(observe(s, seed=seed).intensity))
    np.testing.assert_array_equal(observe(s, seed=np.int64(7)).intensity, observe(s, seed=7).intensity)


@pytest.mark.parametrize(
    "overrides, message",
    [
        (("noise.sigma=1e308",), r"noise.sigma: 1e\+308 makes the noisy series overflow"),
        (("noise.photons_per_unit=1e300",), r"noise.photons_per_unit: .*allowed at most 9.22e\+18 per sample"),
        (("sun.irradiance=1e308",), r"sun.irradiance: 1e\+308 makes the clean signal overflow"),
        (("surfaces.roof.motion.noise_rms=1e300",), r"surfaces.roof.motion: .*overflow"),
        (("surfaces.roof.motion.drive_amplitude=[1e300]",), r"surfaces.roof.motion: .*not finite"),
    ],
)
def test_values_that_overflow_the_series_are_refused(scene, overrides, message):
    s = scene("roof_frame", "sampling.duration=1", *overrides)
    for rtol in (1e-5, None):
        with pytest.raises(SceneError, match=message) as err:
            observe(s, seed=1, rtol=rtol)
        _one_line(err)


def test_a_huge_plate_deflection_is_refused(scene):
    s = scene("roof_elastic", LOW_RES, "sampling.duration=0.05", "surfaces.roof.motion.center_deflection=1e300")
    with pytest.raises(SceneError, match=r"surfaces.roof.motion: .*not finite") as err:
        observe(s, seed=1)
    _one_line(err)


def test_a_black_scene_has_no_sensitivity_and_says_so(scene):
    s = scene(
        "roof_elastic", LOW_RES, "sampling.duration=0.05", "background.material={albedo=0}", "footprint.x=[100, 101]"
    )
    with pytest.raises(SceneError, match="receives no light") as err:
        observe(s, seed=1)
    _one_line(err)


def test_large_but_finite_noise_is_still_simulated(scene):
    o = observe(scene("roof_frame", "sampling.duration=1", "noise.sigma=1e300"), seed=1)
    assert np.all(np.isfinite(o.intensity)) and np.abs(o.intensity).max() > 1e299


def test_the_dense_path_is_refused_above_the_limit_before_it_starts(scene, monkeypatch):
    s = scene("roof_elastic", *FAST)  # 100 samples x 2304 subpixels: 1.8 MB dense, ~1.1 MB otherwise
    monkeypatch.setenv("VIBINVERSE_MEMORY_LIMIT", "1.5e6")
    observe(s, seed=1)
    with pytest.raises(SceneError, match=r"100 samples x 2304 subpixels.*limit 1.5 MB.*footprint.resolution") as err:
        observe(s, seed=1, rtol=None)
    _one_line(err)


def test_scenes_built_in_python_are_checked_too(scene, monkeypatch):
    s = scene("roof_frame", "sampling.duration=1")
    monkeypatch.setenv("VIBINVERSE_MEMORY_LIMIT", "1000")
    with pytest.raises(SceneError, match=r"200 samples .*limit 1000 bytes") as err:
        observe(s, seed=1)
    _one_line(err)

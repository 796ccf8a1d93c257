"""Sensor noise: seeded, with the stated statistics; shot noise and the ADC."""

import numpy as np
import pytest

from forward.sensor import observe
from tests.conftest import FAST


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

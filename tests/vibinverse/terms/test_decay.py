"""The free decay: its likelihood against the dense Gaussian density of a ring whose initial state
is drawn at its onset (from the record's start, or at a blow), its onset found in the data, its
average PSD's integral, its envelope reading, and the modal table's `decays`."""

import math

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.stats import multivariate_normal

from vibinverse.errors import SceneError
from vibinverse.io.series import validate
from vibinverse.models.modal import ModalModel, ModalSpec
from vibinverse.terms import TERMS, DataFacts, FreeDecay, TermSum, White
from vibinverse.terms.decay import envelope_decay, excitation_onset


def _ring_covariance(t, f, zeta, amp, onset):
    """cov of q(t) for (q, q'/w) ~ N(0, amp^2 I) at t[onset], q = 0 before: q(t) = g1 q0 + g2 v0."""
    w = 2 * math.pi * f
    a, b = zeta * w, w * math.sqrt(1 - zeta * zeta)
    u = np.clip(t - t[onset], 0.0, None)
    on = np.arange(t.size) >= onset
    g1 = np.where(on, np.exp(-a * u) * (np.cos(b * u) + a / b * np.sin(b * u)), 0.0)
    g2 = np.where(on, np.exp(-a * u) * np.sin(b * u) / b, 0.0)
    return amp * amp * (np.outer(g1, g1) + w * w * np.outer(g2, g2))


def _ring(t, f, zeta, t0, phase=0.3):
    w = 2 * math.pi * f
    u = np.clip(t - t0, 0.0, None)
    return np.where(t >= t0, np.exp(-zeta * w * u) * np.cos(w * math.sqrt(1 - zeta**2) * u + phase), 0.0)


VALUES = {"decays[0].frequency": 12.0, "decays[0].damping_ratio": 0.02, "decays[0].amplitude": 0.8}


def test_a_ring_from_the_start_has_the_dense_gaussian_likelihood():
    rng = np.random.default_rng(1)
    t = np.arange(300) / 200.0
    y = 5.0 + _ring(t, 12.0, 0.02, 0.0) + 0.1 * rng.standard_normal(t.size)
    model = ModalModel({"modal": {"decays": 1}}, validate(t, y, "x"))
    assert model.onset == 0 and model.spectral is None
    values = {**VALUES, "level": 5.0, "noise.sigma": 0.1}
    cov = _ring_covariance(t, 12.0, 0.02, 0.8, 0) + 0.01 * np.eye(t.size)
    dense = multivariate_normal(np.full(t.size, 5.0), cov).logpdf(y)
    assert model.log_likelihood(values) == pytest.approx(dense, abs=1e-6)
    # the same term composed on its own (`TermSum`) with the white noise
    terms = TermSum(FreeDecay("decays[0]"), White())
    series = validate(t, y - 5.0, "x")
    assert terms.log_likelihood({**VALUES, "noise.sigma": 0.1}, series) == pytest.approx(
        multivariate_normal(np.zeros(t.size), cov).logpdf(y - 5.0), abs=1e-6
    )


def test_a_blow_mid_record_is_found_and_nothing_rings_before_it():
    rng = np.random.default_rng(2)
    t = np.arange(400) / 200.0
    y = _ring(t, 12.0, 0.02, 0.5, phase=-math.pi / 2) + 0.01 * rng.standard_normal(t.size)
    model = ModalModel({"modal": {"decays": 1}}, validate(t, y, "x"))
    assert model.onset in (99, 100)  # the ring starts at sample 100 (from 0, a sine)
    values = {**VALUES, "level": 0.0, "noise.sigma": 0.01}
    cov = _ring_covariance(t, 12.0, 0.02, 0.8, model.onset) + 1e-4 * np.eye(t.size)
    dense = multivariate_normal(np.zeros(t.size), cov).logpdf(y)
    assert model.log_likelihood(values) == pytest.approx(dense, rel=1e-9)
    comp = next(c for c in model.components(values) if c["kind"] == "decay")
    assert comp["onset"] == pytest.approx(t[model.onset])
    assert comp["decay_time"] == pytest.approx(1.0 / (2 * math.pi * 12.0 * 0.02))
    # a draw of the model is zero before the onset but for the white noise
    draw = model.replicate(values, np.random.default_rng(0))
    assert np.std(draw[: model.onset]) < 0.02 < np.std(draw[model.onset : model.onset + 50])


@pytest.mark.parametrize("seed", range(5))
def test_no_blow_is_read_in_a_stationary_record_or_a_ring_from_the_start(seed):
    rng = np.random.default_rng(seed)
    t = np.arange(2000) / 200.0
    assert excitation_onset(t, rng.standard_normal(t.size)) == 0
    assert excitation_onset(t, _ring(t, 9.0, 0.01, 0.0) + 0.1 * rng.standard_normal(t.size)) == 0


def test_the_average_psd_integrates_to_the_rings_mean_square():
    t = np.arange(400) / 100.0
    facts = DataFacts.of(validate(t, np.sin(t), "x"))
    term = FreeDecay("decays[0]")
    f, zeta, amp = 7.0, 0.01, 0.5
    values = {"decays[0].frequency": f, "decays[0].damping_ratio": zeta, "decays[0].amplitude": amp}
    psd = lambda x: float(term.psd(values, np.array([x]), facts)[0])
    total = quad(psd, 0, 2 * f, points=[f], limit=400)[0] + quad(psd, 2 * f, np.inf, limit=400)[0]
    a, span = zeta * 2 * math.pi * f, facts.span
    assert total == pytest.approx(amp**2 * (1 - math.exp(-2 * a * span)) / (2 * a * span), rel=1e-3)
    assert isinstance(TERMS["free_decay"](), FreeDecay)


def test_the_envelope_reads_a_decay_and_not_a_steady_line():
    t = np.arange(1000) / 200.0
    noise = 0.05 * np.random.default_rng(3).standard_normal(t.size)
    assert envelope_decay(_ring(t, 12.0, 0.01, 0.0) + noise, 0.005, 12.0, 0.6) == pytest.approx(0.01, rel=0.25)
    assert envelope_decay(np.cos(2 * math.pi * 12.0 * t) + noise, 0.005, 12.0, 0.6) < 1e-3


def test_the_modal_table_takes_decays_and_names_a_bad_count():
    spec = ModalSpec.from_table({"modal": {"decays": 2}})
    assert spec.decays == 2 and spec.table()["decays"] == 2
    assert "decays[1].amplitude" in spec.names()
    assert "decays" not in ModalSpec.from_table({"modal": {"modes": 1}}).table()
    with pytest.raises(SceneError, match=r"modal\.decays: -1; allowed: an integer in \[0, 20\]"):
        ModalSpec.from_table({"modal": {"decays": -1}})

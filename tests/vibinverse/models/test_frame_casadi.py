"""The frame posterior as a casadi expression, against the numpy posterior (uniform and irregular
stamps)."""

import numpy as np
import pytest

from tests.conftest import SNR10, K, frame_problem
from vibinverse.pipeline import run


@pytest.mark.slow
def test_casadi_objective_equals_the_numpy_posterior_and_its_map_agrees():
    from vibinverse.models.frame_casadi import CasadiFrameObjective

    prob = frame_problem(SNR10, gaps=0.05)
    obj = CasadiFrameObjective(prob)
    z0 = prob.space.to_z(prob.truth())
    rng = np.random.default_rng(0)
    for dz in (0.0, 0.02, 0.1):
        z = z0 + dz * rng.normal(size=z0.size)
        assert obj(z) == pytest.approx(-prob.log_posterior(z), rel=1e-10)
    cas = run(prob, "casadi").summary()
    scipy_map = run(prob, "map").summary()
    assert cas["method"] == "casadi"
    for n in (K + "tilt_frequency", K + "drive_frequency", K + "drive_amplitude"):
        a, b = cas["parameters"][n], scipy_map["parameters"][n]
        assert abs(a["map"] - b["map"]) < 0.1 * b["sd"]
        assert a["sd"] == pytest.approx(b["sd"], rel=0.1)  # exact vs finite-difference Hessian


@pytest.mark.parametrize("duration", ["0.1", "4.03"])
def test_a_record_of_part_blocks_is_padded_with_gaps_that_change_nothing(duration):
    """The casadi recursion runs KALMAN_BLOCK steps a call: 20 samples (fewer than a block, one short
    block) and 806 (16 blocks and 6 steps, the last block padded with 44 gaps) give the numpy
    posterior to 1e-10, with gaps of their own."""
    from vibinverse.models.frame_casadi import KALMAN_BLOCK, CasadiFrameObjective

    prob = frame_problem(SNR10, f"sampling.duration={duration}", gaps=0.05)
    assert prob.series.time.size % KALMAN_BLOCK != 0
    obj = CasadiFrameObjective(prob)
    z0 = prob.space.to_z(prob.truth())
    rng = np.random.default_rng(2)
    for dz in (0.0, 0.1):
        z = z0 + dz * rng.normal(size=z0.size)
        assert obj(z) == pytest.approx(-prob.log_posterior(z), rel=1e-10)


def test_casadi_objective_on_irregular_stamps_equals_the_numpy_posterior():
    """Jittered stamps with dropped frames and gaps: the casadi objective maps the closed-form
    discretization over the distinct steps and gives each Kalman step its own (Phi, Q); it equals
    the numpy posterior (per-step numba filter) to 1e-10 at and around the truth."""
    from vibinverse.io.series import validate
    from vibinverse.models import build_model
    from vibinverse.models.frame_casadi import CasadiFrameObjective
    from vibinverse.posterior import Posterior

    prob = frame_problem(SNR10, "sampling.duration=4", gaps=0.05)
    s = prob.series
    rng = np.random.default_rng(1)
    keep = rng.random(s.time.size) > 0.1
    t = (s.time + rng.uniform(-0.2, 0.2, s.time.size) * s.dt)[keep]
    irregular = Posterior(
        build_model(prob.model.base, validate(t, s.intensity[keep], "irregular", s.scene)),
        dict(zip(prob.space.names, prob.space.priors)),
    )
    assert irregular.model.per_step
    obj = CasadiFrameObjective(irregular)
    z0 = irregular.space.to_z(prob.truth())
    for dz in (0.0, 0.02, 0.1):
        z = z0 + dz * rng.normal(size=z0.size)
        assert obj(z) == pytest.approx(-irregular.log_posterior(z), rel=1e-10)


def test_the_two_state_casadi_filter_equals_the_four_state_posterior_on_a_rectangular_roof():
    """The casadi objective filters the one oscillator the pixel sees (both tilt modes share
    w^2 = 12 k1 / M and zeta whatever the roof's extents; their sum is that oscillator driven by the
    summed intensities). On a 50 m x 20 m roof seen off both tilt axes, with gaps, it equals the
    numpy posterior's filter on the 4 states of the two modes to 1e-10 (rounding alone: 1e-15
    measured)."""
    from vibinverse.models.frame_casadi import CasadiFrameObjective

    prob = frame_problem(
        SNR10,
        "sampling.duration=4",
        "surfaces.roof.y=[-10.0, 10.0]",
        "footprint.y=[-10.0, 10.0]",
        "sensor.azimuth=0.01",
        gaps=0.05,
    )
    obj = CasadiFrameObjective(prob)
    assert obj.seen == [3, 4]  # both tilt modes reach the pixel at first order
    gains = np.abs(prob.model.jac)
    assert gains.min() > 0.3 * gains.max()  # comparably
    z0 = prob.space.to_z(prob.truth())
    rng = np.random.default_rng(2)
    for dz in (0.0, 0.02, 0.1):
        z = z0 + dz * rng.normal(size=z0.size)
        assert obj(z) == pytest.approx(-prob.log_posterior(z), rel=1e-10)

"""The casadi MAP on frame series (sec. 4.2): a solve that stalls in the rounding of the objective
ends with Newton steps at the same optimum IPOPT reaches by itself, and a run given a floor ends
early only when its optimum lies below that floor."""

import logging
import re

import numpy as np
import pytest

import vibinverse.estimators.casadi_map as casadi_map_module
from tests.conftest import frame_problem
from vibinverse.estimators.base import base_result
from vibinverse.estimators.casadi_map import CasadiMap, casadi_map
from vibinverse.estimators.spectral import ranked_starts
from vibinverse.pipeline import AMBIGUITY_MARGIN


@pytest.fixture(
    scope="module",
    params=[
        pytest.param((("sampling.duration=4",), 0), id="4s"),
        pytest.param(((), 1), id="20s", marks=pytest.mark.slow),
    ],
)
def readings(request):
    """The sec. 4.2 posterior (4 s, 800 samples, seed 0, or the scene's 20 s, 4000 samples, seed 1:
    ~1 s to compile and 1-3 s a solve), the MAP from the spectral starts, and the start of the
    exchanged reading (tilt resonance and drive line swapped) as the pipeline forms it. IPOPT stalls
    on both (on 20 s it stalls for seeds 1 and 3-7, not 0 and 2, since the base force is held over
    each frame; the MAP from the spectral starts took 8.6 s for seed 1 but 144 s for seeds 3 and 4
    on a slow machine, so the test uses seed 1; on 4 s, from the starts ranked by their excess over
    the spectrum's background, seeds 0, 4-6 and 8 of 0-9 stall, seed 2 no longer does)."""
    overrides, seed = request.param
    problem = frame_problem(*overrides, seed=seed)
    best = casadi_map(problem, ranked_starts(problem))
    point = problem.values(best.z)
    ((_, values),) = problem.model.alternatives(point, problem.space.names)
    space = problem.space
    exchanged = {n: p.inside(values.get(n, point[n])) for n, p in zip(space.names, space.priors)}
    return problem, best, exchanged


def test_a_stalled_solve_ends_with_newton_steps_at_the_optimum_ipopt_reaches(readings, monkeypatch, caplog):
    problem, best, _ = readings
    # IPOPT alone: never judged stalled, it runs until its own (acceptable-level) termination
    monkeypatch.setattr(casadi_map_module, "STALL_STEP", -1.0)
    alone = casadi_map(problem, ranked_starts(problem))
    monkeypatch.undo()
    with caplog.at_level(logging.DEBUG, logger="vibinverse.estimators.casadi_map"):
        again = casadi_map(problem, ranked_starts(problem))
    assert "stalled" in caplog.text  # this series stalls (f ~ 4e3-2e4 summed over the Kalman steps)
    np.testing.assert_array_equal(again.z, best.z)  # deterministic
    # IPOPT's own end is within ~1e-7 (in z) of the optimum the Newton steps reach: the values, and
    # the Laplace sds (from the exact Hessian there), agree to 1e-6 relative
    a, b = problem.values(alone.z), problem.values(best.z)
    for n in problem.space.names:
        assert b[n] == pytest.approx(a[n], rel=1e-6), n
    sd_a, sd_b = np.sqrt(np.diag(alone.cov_z)), np.sqrt(np.diag(best.cov_z))
    np.testing.assert_allclose(sd_b, sd_a, rtol=1e-5)
    # and the Newton point is no worse: its log posterior is the higher one, up to f's rounding
    assert best.log_post >= alone.log_post - 1e-8 * abs(alone.log_post)


def test_the_exchanged_reading_ends_early_below_the_floor_and_runs_on_above_it(readings):
    problem, best, exchanged = readings
    full = casadi_map(problem, [exchanged])  # hundreds (4 s) to thousands (20 s) of units below the best
    assert full.log_post < best.log_post - 10 * AMBIGUITY_MARGIN
    # the pipeline's floor (the best less the ambiguity margin): ended early, and rightly so
    floor = best.log_post - AMBIGUITY_MARGIN
    result = CasadiMap().estimate(problem, _start(problem, exchanged), floor=floor)
    assert "abandoned" in result.diagnostics
    assert result.log_post <= full.log_post < floor
    # a floor just below the exchanged reading's own optimum: the run must reach that optimum
    # (had it been the better reading, it would be found and reported); the cut needs the Newton
    # model to miss the descent still to come by CUT_FACTOR, whatever the margin
    for margin in (1e-3, 1.0):
        reached = CasadiMap().estimate(problem, _start(problem, exchanged), floor=full.log_post - margin)
        assert "abandoned" not in reached.diagnostics
        assert reached.log_post == pytest.approx(full.log_post, abs=1e-6)


def test_a_better_reading_is_never_ended_by_the_floor_of_a_worse_one(readings):
    """The alternative wins: the exchanged reading taken as the best so far, its floor given to a
    run from the spectral start, which must reach the true optimum unhindered."""
    problem, best, exchanged = readings
    worse = casadi_map(problem, [exchanged])
    result = CasadiMap().estimate(problem, None, floor=worse.log_post - AMBIGUITY_MARGIN)
    assert "abandoned" not in result.diagnostics
    assert result.log_post == pytest.approx(best.log_post, abs=1e-6)
    np.testing.assert_allclose(result.z, best.z, atol=1e-7)


@pytest.mark.slow
def test_a_stall_at_the_optimum_within_the_rounding_ends_there(caplog):
    """The 20 s series, seed 3: IPOPT stalls after 18 iterations where the rounded gradient asks
    for steps of 2-5e-8 in z (1e-7 posterior sd) that change f only by its rounding (+-3e-7). The
    Newton steps end there; IPOPT left to itself ran to its 300-iteration limit (280 s on a slow
    machine). Oracle: the numpy posterior falls on both sides of the point along each principal
    axis of the Laplace covariance (+-0.01 sd lowers it by 5e-5, far above its rounding), which
    holds only within ~5e-3 sd of the maximum."""
    problem = frame_problem(seed=3)
    with caplog.at_level(logging.DEBUG, logger="vibinverse.estimators.casadi_map"):
        best = casadi_map(problem, ranked_starts(problem))
    stalls = [int(n) for n in re.findall(r"stalled after (\d+) iterations", caplog.text)]
    assert stalls and max(stalls) < 40 and "finished with Newton steps" in caplog.text
    at = problem.log_posterior(best.z)
    assert at == pytest.approx(best.log_post, abs=1e-6)
    w, v = np.linalg.eigh(best.cov_z)
    for sd, axis in zip(np.sqrt(w), v.T):
        for sign in (-1.0, 1.0):
            assert problem.log_posterior(best.z + sign * 0.01 * sd * axis) < at


def _start(problem, values):
    """A single start as the pipeline hands it to the MAP stage."""
    return base_result(problem, "start", values, starts=[values])

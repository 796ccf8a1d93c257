"""Fisher information and Cramer-Rao bounds: the response bound against the design bound, and
the Whittle covariance information against the exact trace formula."""

import math

import numpy as np
import pytest

from tests.conftest import K, simulate, table
from vibinverse.design.metrics import evaluate
from vibinverse.models import build_model
from vibinverse.posterior import Posterior


def test_fisher_bound_equals_the_design_bound_and_the_sigma_bound():
    """Two implementations of the same Cramer-Rao bound: `fisher.response_fisher` (nuisances gain
    and phase) and `design.metrics` (nuisances DC and time shift) give the same frequency and
    amplitude sds: a single line's phase is its time shift, and the mean level pins the gain (to
    3e-5), so that it acts as a DC offset does. sigma's bound is sigma / sqrt(2N) exactly."""
    from vibinverse.fisher import crlb_from_fisher, response_fisher

    table, series = simulate("roof_elastic", seed=4)
    problem = Posterior(build_model(table, series))
    names = problem.space.names
    bound = crlb_from_fisher(response_fisher(problem.model, problem.truth(), names), names)
    design = evaluate(table, [K + "frequency", K + "center_deflection"], {})
    for n in (K + "frequency", K + "center_deflection"):
        assert bound[n] == pytest.approx(design[f"crlb {n}"], rel=1e-3)
    assert bound["noise.sigma"] == pytest.approx(0.05 / np.sqrt(2 * series.time.size), rel=1e-9)


def test_whittle_covariance_information_matches_the_exact_trace_formula():
    from vibinverse.fisher import covariance_fisher, covariance_fisher_dense, crlb_from_fisher, mean_fisher
    from vibinverse.io.series import Series
    from vibinverse.models.frame import FrameModel

    tab = table(
        "roof_frame",
        "noise.sigma=0.6",
        "sampling.fs=40",
        "sampling.duration=15",
        "surfaces.roof.motion.drive_frequency=[7.0]",
    )
    t = np.arange(600) / 40.0
    like = FrameModel(tab, Series(t, np.zeros(t.size), "test"))
    names = [K + "tilt_frequency", K + "tilt_damping_ratio", K + "noise_rms", "noise.sigma"]
    values = dict(zip(names, (2 * math.sqrt(3), 0.0137832223855448, 1e-4, 0.6)))
    fm = mean_fisher(like, values, names)
    whittle = crlb_from_fisher(fm + covariance_fisher(like, values, names), names)
    exact = crlb_from_fisher(fm + covariance_fisher_dense(like, values, names), names)
    for n in names:  # 15 s is ~4.5 decay times of the tilt mode: Whittle's O(decay/duration) error
        assert whittle[n] == pytest.approx(exact[n], rel=0.2)

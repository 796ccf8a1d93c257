"""The deterministic posterior as a casadi expression: equal to the numpy posterior, its MAP equal to
the scipy MAP, and refused where a frequency moves the shapes."""

import json

import numpy as np
import pytest

from tests.conftest import LOW_RES, G, K, simulate
from vibinverse.models import build_model
from vibinverse.pipeline import run
from vibinverse.posterior import Posterior
from vibinverse.priors import Prior


def test_casadi_objective_equals_the_numpy_posterior_with_gaps_and_shot_noise():
    from vibinverse.models.deterministic_casadi import CasadiResponseObjective

    table, series = simulate("roof_elastic", LOW_RES, "noise.photons_per_unit=1e4", seed=3, gaps=0.05)
    problem = Posterior(build_model(table, series))
    objective = CasadiResponseObjective(problem)
    z0 = problem.space.to_z(problem.truth())
    for dz in np.random.default_rng(0).normal(0.0, 0.01, (3, z0.size)):
        assert objective(z0 + dz) == pytest.approx(-problem.log_posterior(z0 + dz), rel=1e-9)


def test_casadi_map_equals_the_scipy_map_and_falls_back_where_shapes_move():
    from vibinverse.errors import Unsupported
    from vibinverse.models.deterministic_casadi import CasadiResponseObjective

    table, series = simulate("roof_elastic", LOW_RES, seed=3)
    problem = Posterior(build_model(table, series))
    fast = run(problem, "casadi", progress=False).summary()
    slow = run(problem, "map", progress=False).summary()
    assert fast["method"] == "casadi" and slow["method"] == "map"
    for n, p in slow["parameters"].items():
        assert fast["parameters"][n]["median"] == pytest.approx(p["median"], abs=0.01 * p["sd"])
        assert fast["parameters"][n]["sd"] == pytest.approx(p["sd"], rel=0.01)
    # a Rayleigh frequency changes the wave's shape; a plate driven through its boundary has q ~ w^2
    ground, gs = simulate("ground_rayleigh", LOW_RES, "noise.sigma=3e-6")
    with pytest.raises(Unsupported, match="frequency"):
        CasadiResponseObjective(Posterior(build_model(ground, gs)))
    fixed_f = {
        G + "amplitude[0]": Prior("uniform", (0.0, 0.01)),
        G + "phase[0]": Prior("uniform", (-np.pi, np.pi)),
        "noise.sigma": Prior("loguniform", (1e-7, 1e-4)),
    }
    assert run(Posterior(build_model(ground, gs), fixed_f), "casadi", progress=False).summary()["method"] == "casadi"
    boundary = json.loads(json.dumps(table))
    motion = boundary["surfaces"]["roof"]["motion"]
    del motion["center_deflection"]
    motion.update({"boundary_amplitude": 1e-4, "density": 7850.0, "shear_modulus": 8e10})
    with pytest.raises(Unsupported, match="frequency"):
        CasadiResponseObjective(
            Posterior(
                build_model(boundary, series),
                {K + "frequency": Prior("uniform", (30.0, 50.0)), "noise.sigma": Prior("loguniform", (1e-3, 1.0))},
            )
        )

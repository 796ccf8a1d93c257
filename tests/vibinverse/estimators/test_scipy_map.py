"""MAP results: Laplace intervals formed in the unconstrained space stay inside the prior."""

import numpy as np

import vibinverse as vi
from vibinverse.io.builtin import builtin_scene

K = "surfaces.roof.motion."


def test_laplace_intervals_of_positive_parameters_never_go_below_zero():
    # a deflection of 2e-7 m is below the noise (the line is not detected): its posterior piles up
    # at the prior's lower bound 0, where MAP -/+ 1.645 sd went negative
    scene = vi.load_scene(builtin_scene("roof_elastic"), [f"{K}center_deflection=2e-7", "noise.sigma=0.2"])
    obs = vi.simulate(scene, seed=4)
    free = {
        K + "center_deflection": "uniform(0, 0.01)",
        K + "phase": "uniform(-pi, pi)",
        "noise.sigma": "loguniform(0.01, 1)",
    }
    for method in ("map", "casadi"):
        result = vi.fit(vi.series(obs.time, obs.intensity, scene=scene), scene, method=method, free=free)
        for name, p in result.summary()["parameters"].items():
            lo, hi = p["prior_bounds"]
            assert lo <= p["q05"] <= p["map"] <= p["q95"] <= hi, (method, name, p)
        amp = result.summary()["parameters"][K + "center_deflection"]
        assert amp["map"] - 1.645 * amp["sd"] < 0 <= amp["q05"]  # the symmetric interval would have gone negative
        assert not result.detections[0].detected
    assert np.isfinite(amp["sd"])

"""The fitting pipeline: the auto chain runs and times every stage, past a declined SINDy."""

import pytest

from tests.conftest import frame, series
from vibinverse.models import build_model
from vibinverse.pipeline import run
from vibinverse.posterior import Posterior


@pytest.mark.slow
def test_auto_chains_spectral_sindy_casadi_emcee_and_times_each(tmp_path):
    table = frame("noise.sigma=0.2")
    s = series(table, 4)
    summary = run(
        Posterior(build_model(table, s)), "auto", backend=tmp_path / "c.h5", progress=False, max_steps=300
    ).summary()
    assert {"spectral_s", "sindy_s", "casadi_s", "mcmc_s"} <= set(summary["timing"])
    assert summary["diagnostics"]["sindy"]["status"] == "ok"
    # a declined SINDy does not stop the chain
    table = frame("noise.sigma=0.2", "sensor.inclination=pi/3")
    s = series(table, 4)
    summary = run(Posterior(build_model(table, s)), "sindy", progress=False).summary()
    assert summary["diagnostics"]["sindy"]["status"] == "declined" and summary["method"] == "spectral"

"""The HTML report and its warnings."""

import pytest

from tests.conftest import fit_args, run_cli


@pytest.mark.slow
def test_report_renders_table_figures_and_warnings(short_data):
    d = short_data
    if not (d / "full.nc").exists():
        assert run_cli(*fit_args(d, "full")).returncode == 0
    r = run_cli("report", str(d / "full.nc"), "-o", str(d / "rep"))
    assert r.returncode == 0, r.stderr
    html = (d / "rep" / "report.html").read_text()
    assert "<table>" in html and html.count("data:image/png;base64,") >= 4
    assert "not converged" in html  # 400 steps is far from 50 tau: the report must say so


def test_bound_warning_is_for_a_posterior_cut_by_its_prior_not_for_a_wide_prior():
    """A 1 mm amplitude under uniform(0, 0.1) and sigma under loguniform(1e-7, 4) sit far from
    their bounds in posterior sds (and, for sigma, in the prior's log scale); a posterior piled
    against 0 does not."""
    from vibinverse.report import warnings_for

    def summary(median, q05, q95, prior, bounds):
        p = {"median": median, "q05": q05, "q95": q95, "prior": prior, "prior_bounds": bounds}
        return {"diagnostics": {}, "parameters": {"x": p}}

    assert warnings_for(summary(0.00099, 0.00098, 0.001, "uniform(0, 0.1)", [0.0, 0.1]), None, ["x"]) == []
    assert warnings_for(summary(0.0467, 0.0446, 0.0492, "loguniform(7e-08, 4.2)", [7e-8, 4.2]), None, ["x"]) == []
    cut = warnings_for(summary(0.0005, 0.00003, 0.0015, "uniform(0, 0.1)", [0.0, 0.1]), None, ["x"])
    assert len(cut) == 1 and "sits at a bound" in cut[0]
    wide = warnings_for(summary(0.5, 0.05, 0.95, "uniform(0, 1)", [0.0, 1.0]), None, ["x"])
    assert len(wide) == 1 and "not informed" in wide[0]

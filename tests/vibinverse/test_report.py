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


# ------------------------------------------------------------------ crafted and incomplete result files

XSS_IMG = "<img src=x onerror=alert(1)>"
XSS_SCRIPT = "<script>alert(1)</script>"


@pytest.fixture(scope="module")
def result_file(tmp_path_factory):
    """A valid result netCDF of a quick spectral fit of the plate scene."""
    import vibinverse as vi
    from vibinverse.io.builtin import builtin_scene

    scene = vi.load_scene(builtin_scene("roof_elastic"))
    obs = vi.simulate(scene, seed=1)
    path = tmp_path_factory.mktemp("result") / "result.nc"
    vi.fit(vi.series(obs.time, obs.intensity, scene=scene), scene, method="spectral").to_netcdf(path)
    return path


def _craft(src, dst):
    """`src` with every user-controlled string of its summary replaced by markup."""
    import json

    import h5py

    dst.write_bytes(src.read_bytes())
    with h5py.File(dst, "a") as f:
        attrs = f["observed_data"].attrs
        summary = json.loads(attrs["vibinverse_summary"])
        names = json.loads(attrs["parameter_names"])
        first = next(iter(summary["parameters"]))
        params = {(XSS_IMG if n == first else n): p for n, p in summary["parameters"].items()}
        params[XSS_IMG]["prior"] = XSS_IMG
        summary["parameters"] = params
        summary["timing"] = {XSS_SCRIPT: 0.5, "fit": None}
        summary["data"]["source"] = XSS_IMG
        summary["data"]["description"] = XSS_SCRIPT
        summary["method"] = XSS_SCRIPT
        summary["diagnostics"].update(
            {
                XSS_SCRIPT: XSS_IMG,
                "multimodal": [XSS_IMG],
                f"{XSS_SCRIPT}_detected": False,
                f"{XSS_SCRIPT}_delta_loglike": 1.0,
                f"{XSS_SCRIPT}_threshold": XSS_SCRIPT,
                "sindy": {"status": "ok", "equation": XSS_SCRIPT, "misfit": XSS_IMG},
                "converged": False,
                "rhat_max": XSS_IMG,
            }
        )
        attrs["vibinverse_summary"] = json.dumps(summary)
        attrs["parameter_names"] = json.dumps({k: (XSS_IMG if v == first else v) for k, v in names.items()})
    return dst


def test_a_crafted_result_renders_no_live_markup(result_file, tmp_path):
    from vibinverse.report import write_report

    page = write_report(_craft(result_file, tmp_path / "crafted.nc"), tmp_path).read_text()
    assert "<script" not in page.lower()  # the report has no script of its own: any would be injected
    assert "<img src=x" not in page and page.count("onerror=") == page.count("&lt;img src=x onerror=")
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in page and "&lt;img src=x onerror=alert(1)&gt;" in page


def test_a_report_of_nulls_and_non_finite_numbers(tmp_path):
    """Unbounded priors, NaN R-hat, no sd and no predictive bands: the page renders, the warnings
    say what they can."""
    from tests.conftest import unbounded_result
    from vibinverse.report import warnings_for, write_report

    result = unbounded_result()
    page = write_report(result.to_netcdf(tmp_path / "r.nc"), tmp_path).read_text()
    assert "not converged" in page and "noise.sigma" in page
    # the same summary as strict JSON gives nulls (a result.json read back by json.load)
    summary = {
        "diagnostics": {"converged": False, "rhat_max": None, "tau_max": None, "n_steps": None},
        "parameters": {
            "x": {"median": 0.5, "q05": 0.4, "q95": 0.6, "prior": "normal(0, 1)", "prior_bounds": [None, None]}
        },
    }
    warn = warnings_for(summary, None, ["x"])
    assert len(warn) == 1 and "not converged (R-hat n/a" in warn[0]

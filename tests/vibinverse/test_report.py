"""The HTML report: the verdict first, the parameters, the figures, the warnings; crafted files.

`hand_made_result` writes a result netCDF by hand, in exactly the shapes `FitResult.to_netcdf`
writes (posterior or approximate_posterior, log_likelihood, posterior_predictive, sample_stats,
observed_data, constant_data with the residuals; a summary with units, long names, R-hat and ESS,
the approximation, the residual checks and the false-alarm probabilities), so that these tests
and the browser test (`test_report_browser.py`) do not depend on an estimator's run.
"""

import io
import json
import math
import os
import re
import warnings

import numpy as np
import pytest

from tests.conftest import fit_args, run_cli

K = "surfaces.roof.motion."
#: name: (truth, posterior sd, units, long name, prior, prior bounds)
HAND_PARAMETERS = {
    K + "tilt_frequency": (3.466, 0.004, "Hz", "tilt frequency", "uniform(0.6, 50)", [0.6, 50.0]),
    K + "tilt_damping_ratio": (0.01, 0.001, "1", "tilt damping ratio", "loguniform(0.001, 0.5)", [0.001, 0.5]),
    K + "drive_frequency": (10.0, 0.0001, "Hz", "drive frequency", "uniform(0.6, 50)", [0.6, 50.0]),
    K + "drive_amplitude": (1e-3, 1e-5, "m", "drive amplitude", "uniform(0, 0.05)", [0.0, 0.05]),
    K + "drive_phase": (0.3, 0.02, "rad", "drive phase", "uniform(-3.14159, 3.14159)", [-3.14159, 3.14159]),
    K + "noise_rms": (1e-4, 5e-6, "m", "RMS of the white base motion", "loguniform(1e-07, 0.1)", [1e-7, 0.1]),
    "noise.sigma": (0.3, 0.01, "DN", "sensor noise standard deviation", "loguniform(1e-08, 1000)", [1e-8, 1e3]),
}


def _safe(name):
    return name.replace(".", "__").replace("[", "_").replace("]", "")


def _resonance(rng, n, f, zeta, dt, scale):
    """An AR(2) process with its spectral peak at f: a noise-driven resonance."""
    r = math.exp(-2 * math.pi * f * zeta * dt)
    a1, a2 = 2 * r * math.cos(2 * math.pi * f * dt), -(r**2)
    e = rng.normal(scale=scale, size=n + 200)
    x = np.zeros(n + 200)
    for i in range(2, n + 200):
        x[i] = a1 * x[i - 1] + a2 * x[i - 2] + e[i]
    return x[200:]


def hand_made_result(
    path,
    kind="mcmc",
    *,
    n=1000,
    dt=0.01,
    walkers=8,
    draws=1000,
    replicates=25,
    predictive=True,
    residuals=True,
    checks=True,
    false_alarm=True,
    converged=True,
    units="DN",
    seed=0,
):
    """A frame-like result (a 3.466 Hz resonance and a 10 Hz drive in 0.3 DN noise, 3 % gaps and
    one 0.2 s block) written to `path` in the result contract's shapes. `kind`: "mcmc" (a
    posterior group, R-hat and ESS) or "laplace" (an approximate_posterior group, no R-hat)."""
    import arviz as az
    import xarray as xr

    from vibinverse import inference_data as idata_io

    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    gaps = rng.random(n) < 0.03
    gaps[n // 3 : n // 3 + 20] = True
    truth = {k: v[0] for k, v in HAND_PARAMETERS.items()}
    drive = 0.5 * np.cos(2 * np.pi * 10.0 * t + 0.3)
    mean = 100.0 + drive

    def series(r):
        y = mean + _resonance(r, n, 3.466, 0.01, dt, 0.1) + r.normal(scale=0.3, size=n)
        y[gaps] = np.nan
        return y

    y = series(rng)
    names = list(HAND_PARAMETERS)
    chains = walkers if kind == "mcmc" else 1
    n_draws = draws if kind == "mcmc" else 1000
    noise = rng.normal(size=(chains, n_draws, len(names)))
    for i in range(1, n_draws):  # autocorrelated draws: ESS below the number of draws
        noise[:, i] = 0.5 * noise[:, i - 1] + 0.866 * noise[:, i]
    values = np.array([truth[k] for k in names]) + noise * np.array([HAND_PARAMETERS[k][1] for k in names])
    cf = lambda u, ln: {"units": u, "long_name": ln}
    draw_ds = xr.Dataset(
        {_safe(k): (("chain", "draw"), values[..., j], cf(*HAND_PARAMETERS[k][2:4])) for j, k in enumerate(names)},
        coords={"chain": np.arange(chains), "draw": np.arange(n_draws)},
    )
    groups = {}
    if kind == "mcmc":
        groups["posterior"] = draw_ds
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            conv = az.summary(draw_ds, kind="diagnostics", round_to="none")
        groups["sample_stats"] = xr.Dataset({"lp": (("chain", "draw"), rng.normal(-500, 2, (chains, n_draws)))})
    else:
        groups["approximate_posterior"] = draw_ds.assign_attrs(approximation="laplace")
        conv = None
    sample = {"time_index": np.arange(n)}
    if predictive:
        keep = np.unique(np.linspace(0, n_draws - 1, max(1, replicates // chains + 1)).round().astype(int))
        reps = np.array([[series(rng) for _ in keep] for _ in range(chains)])
        coords = {"chain": np.arange(chains), "draw": keep, **sample}
        dims = ("chain", "draw", "time_index")
        loglik = -0.5 * ((reps - mean) / 0.3) ** 2
        groups["log_likelihood"] = xr.Dataset(
            {"intensity": (dims, loglik, cf("1", "pointwise log-likelihood"))}, coords
        )
        groups["posterior_predictive"] = xr.Dataset(
            {"intensity": (dims, reps, cf(units, "replicate intensity"))}, coords
        )
        if kind != "mcmc":
            for g in ("log_likelihood", "posterior_predictive"):
                groups[g].attrs["approximation"] = "laplace"
    flat = values.reshape(-1, len(names))
    params = {}
    for j, k in enumerate(names):
        d = flat[:, j]
        q05, q50, q95 = np.percentile(d, [5, 50, 95])
        _, _, u, long_name, prior, bounds = HAND_PARAMETERS[k]
        params[k] = {
            "median": q50,
            "mean": d.mean(),
            "sd": d.std(ddof=1),
            "q05": q05,
            "q95": q95,
            "map": truth[k],
            "truth": truth[k],
            "rhat": None if conv is None else float(conv.loc[_safe(k), "r_hat"]),
            "ess_bulk": None if conv is None else float(conv.loc[_safe(k), "ess_bulk"]),
            "ess_tail": None if conv is None else float(conv.loc[_safe(k), "ess_tail"]),
            "prior": prior,
            "prior_bounds": bounds,
            "units": u if u != "DN" else units,
            "long_name": long_name,
        }
    diagnostics = {}
    if kind == "mcmc":
        diagnostics.update(
            {
                "converged": converged,
                "rhat_max": float(conv["r_hat"].max()) if converged else 1.3,
                "ess_min": float(conv[["ess_bulk", "ess_tail"]].min().min()) if converged else 40.0,
                "n_steps": 4000,
                "tau_max": 40.0,
            }
        )
        if not converged:
            for p in params.values():
                p["rhat"], p["ess_bulk"] = 1.3, 40.0
    else:
        diagnostics["hessian_positive_definite"] = True
    for what, gain in (("drive", 900.0), ("resonance", 240.0)):
        diagnostics.update({f"{what}_delta_loglike": gain, f"{what}_threshold": 18.7, f"{what}_detected": True})
        if false_alarm:
            diagnostics[f"{what}_false_alarm_probability"] = min(1.0, 500 * math.exp(-gain) * math.sqrt(gain))
    if checks:
        diagnostics["residual_checks"] = {
            "ljung_box_p": 0.41,
            "lags": 20,
            "normality_p": 0.62,
            "white": True,
            "normal": True,
            "alpha": 0.01,
        }
    summary = {
        "method": "mcmc" if kind == "mcmc" else "map",
        "approximation": None if kind == "mcmc" else "laplace",
        "parameters": params,
        "diagnostics": diagnostics,
        "timing": {f"{'mcmc' if kind == 'mcmc' else 'map'}_s": 12.5},
        "data": {
            "source": "hand-made",
            "description": f"{n} samples over {(n - 1) * dt:g} s, uniform at {1 / dt:g} Hz; {int(gaps.sum())} gaps",
            "n_gaps": int(gaps.sum()),
            "n_samples": n,
            "intensity_units": units,
            "time_units": "s",
        },
    }
    attrs = {"vibinverse_summary": json.dumps(summary), "parameter_names": json.dumps({_safe(k): k for k in names})}
    groups["observed_data"] = xr.Dataset(
        {"intensity": ("time_index", y, cf(units, "pixel intensity"))}, coords=sample, attrs=attrs
    )
    constant = {
        "time": ("time_index", t, cf("s", "time")),
        "model_mean": ("time_index", mean, cf(units, "model mean at the point estimate")),
        "model_q05": ("time_index", mean - 0.01, cf(units, "model mean, 5 % quantile over the draws")),
        "model_q95": ("time_index", mean + 0.01, cf(units, "model mean, 95 % quantile over the draws")),
    }
    if residuals:
        r = rng.normal(size=n)
        r[gaps] = np.nan
        constant["residual"] = ("time_index", r, cf("1", "standardized one-step residual at the point estimate"))
    groups["constant_data"] = xr.Dataset(constant, coords=sample)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        idata_io.to_netcdf(idata_io.build(groups), path)
    return path


def real_mcmc_result(path, max_steps=1500):
    """A real result: emcee on 6 s of the sec. 4.2 frame (`vibinverse.api.fit`), written to `path`."""
    import vibinverse as vi
    from vibinverse.io.builtin import builtin_scene

    scene = vi.load_scene(builtin_scene("roof_frame"), overrides=["noise.sigma=0.6", "sampling.duration=6"])
    obs = vi.simulate(scene, seed=3)
    result = vi.fit(vi.series(obs.time, obs.intensity, scene=scene), scene, method="mcmc", max_steps=max_steps)
    return result.to_netcdf(path)


def sections(page):
    """The ids of the page's top-level blocks (sections and figures), in order."""
    body = page[page.index("<body>") :]
    return re.findall(r'<(?:section|figure)[^>]* id="([^"]+)"', body)


def table_cells(page, css_class):
    return re.findall(rf'<td class="{css_class}">([^<]*)</td>', page)


@pytest.mark.slow
def test_report_renders_table_figures_and_warnings(short_data):
    d = short_data
    results = lambda: [p for p in (d / "full.nc", d / "full" / "result.nc") if p.exists()]
    if not results():
        r = run_cli(*fit_args(d, "full"))
        assert r.returncode == 0, r.stderr
    r = run_cli("report", str(results()[0]), "-o", str(d / "rep"))
    assert r.returncode == 0, r.stderr
    html = (d / "rep" / "report.html").read_text()
    assert "<table>" in html and html.count("data:image/png;base64,") >= 4
    assert "not converged" in html  # 400 steps is far from 50 tau: the report must say so
    assert sections(html)[0] == "verdict"


# ------------------------------------------------------------------ hand-made results in the contract's shapes


@pytest.fixture(scope="module")
def pages(tmp_path_factory):
    """kind -> (result path, report page) of the hand-made results, written once for the module."""
    from vibinverse.report import write_report

    out = {}
    for kind, kw in (
        ("mcmc", {}),
        ("laplace", {"kind": "laplace"}),
        ("bare", {"kind": "laplace", "predictive": False, "residuals": False, "checks": False, "false_alarm": False}),
        ("unconverged", {"converged": False, "units": "1", "walkers": 4, "draws": 200}),
    ):
        d = tmp_path_factory.mktemp(kind)
        path = hand_made_result(d / "result.nc", **kw)
        out[kind] = (path, write_report(path, d).read_text())
    return out


def test_the_verdict_comes_first_then_warnings_parameters_and_figures(pages):
    page = pages["mcmc"][1]
    assert sections(page) == [
        "verdict",
        "warnings",
        "about",
        "parameters",
        "fig-0",
        "fig-1",
        "fig-2",
        "fig-3",
        "fig-4",
        "fig-5",
        "diagnostics",
    ]
    titles = re.findall(r'<figure id="fig-\d+"><h2>([^<]+)</h2>', page)
    assert titles == [
        "Data and posterior predictive",
        "Residuals",
        "Phase-folded data",
        "Power spectral density",
        "Traces",
        "Corner plot",
    ]
    assert page.count("data:image/png;base64,") == 6
    verdict_box = page[page.index('<section class="verdict') : page.index('id="warnings"')]
    assert 'drive line</b> detected at <span class="val">10.00000 ± 0.00010 Hz</span>' in verdict_box
    assert 'tilt resonance</b> detected at <span class="val">3.466 ± 0.004 Hz</span>' in verdict_box
    assert "false-alarm probability" in verdict_box and "Can this be trusted? Yes." in verdict_box
    assert 'class="verdict yes"' in verdict_box


def test_rhat_and_ess_are_arviz_summary_of_the_posterior(pages):
    """The report's R-hat, bulk and tail ESS equal `arviz.summary` on the posterior group, to the
    printed precision (3 decimals, whole draws)."""
    import arviz as az

    path, page = pages["mcmc"]
    idata = az.from_netcdf(str(path), engine="h5netcdf")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        table = az.summary(idata.posterior, round_to="none")
    names = list(HAND_PARAMETERS)
    rhat, bulk, tail = (table_cells(page, c) for c in ("rhat", "ess-bulk", "ess-tail"))
    assert len(rhat) == len(bulk) == len(tail) == len(names)
    for i, n in enumerate(names):
        row = table.loc[_safe(n)]
        assert rhat[i] == f"{row['r_hat']:.3f}" and bulk[i] == f"{row['ess_bulk']:.0f}"
        assert tail[i] == f"{row['ess_tail']:.0f}"
    assert "<th>R-hat</th><th>ESS bulk</th><th>ESS tail</th>" in page


@pytest.mark.slow
def test_a_real_mcmc_report(tmp_path):
    """On a real emcee result: the verdict first, R-hat and ESS equal to arviz.summary's, the
    residuals and the model's PSD from the posterior predictive replicates."""
    import html

    import arviz as az

    from vibinverse.report import write_report
    from vibinverse.result import read_result
    from vibinverse.verdict import verdict

    path = real_mcmc_result(tmp_path / "result.nc")
    page = write_report(path, tmp_path).read_text()
    summary, idata = read_result(path)
    assert sections(page)[:4] == ["verdict", "warnings", "about", "parameters"]
    safe = {v: k for k, v in json.loads(idata.observed_data.attrs["parameter_names"]).items()}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        table = az.summary(idata.posterior, round_to="none")
    rhat, bulk, tail = (table_cells(page, c) for c in ("rhat", "ess-bulk", "ess-tail"))
    for i, n in enumerate(summary["parameters"]):
        row = table.loc[safe[n]]
        assert (rhat[i], bulk[i], tail[i]) == (
            f"{row['r_hat']:.3f}",
            f"{row['ess_bulk']:.0f}",
            f"{row['ess_tail']:.0f}",
        )
    assert "Residuals</h2>" in page and "posterior predictive replicates, computed the same way" in page
    v = verdict(summary)
    assert v.lines and all(f"<b>{html.escape(ln.label)}</b>" in page for ln in v.lines)


def test_an_approximation_is_labelled_and_has_no_rhat(pages):
    page = pages["laplace"][1]
    assert "90 % interval (Laplace approximation)" in page
    assert "R-hat</th>" not in page and "ESS bulk" not in page and not table_cells(page, "rhat")
    assert not re.search(r"(?i)\bnan\b", re.sub(r"<img[^>]*>", "", page))
    assert "Traces" not in page and "Corner plot" not in page  # no real draws
    assert "Can this be trusted? Yes." in page and "Laplace approximation (no sampler, so no R-hat)" in page


def test_a_bare_result_degrades_gracefully(pages):
    """No predictive replicates, no residuals, no residual checks, no false-alarm probabilities."""
    page = pages["bare"][1]
    assert "Can this be trusted? Not decided." in page and "residuals not checked" in page
    assert "Residuals</h2>" not in page
    assert "no posterior predictive replicates in the result, so no model PSD" in page
    assert "model mean 5-95 % over the draws" in page  # the band from constant_data
    assert "false-alarm probability n/a" in page
    assert page.count("data:image/png;base64,") == 3  # data, folded, PSD


def test_an_unconverged_run_is_not_trusted_and_units_unknown_read_arbitrary(pages):
    page = pages["unconverged"][1]
    assert 'class="verdict no"' in page and "Can this be trusted? No." in page
    assert "has not converged (R-hat 1.300, ESS 40" in page
    assert "intensity in arbitrary units" in page


def test_the_page_is_self_contained_and_phone_ready(pages):
    for _, page in pages.values():
        assert '<meta name="viewport" content="width=device-width, initial-scale=1">' in page
        assert "max-width:1000px" in page and "img{max-width:100%" in page
        assert page.count('<div class="table-wrap"><table>') == 2  # parameters and diagnostics scroll in a box
        without_images = re.sub(r'src="data:image/png;base64,[^"]*"', "", page)
        assert not re.search(r"(?i)https?:|//[a-z]|<script|<link|@import|url\(|@font-face", without_images)
        assert re.findall(r'<img src="([^"]{0,22})', page) == ["data:image/png;base64,"] * page.count("<img")


def test_psd_is_calibrated_with_gaps():
    """White noise of sd 2 with 30 % gaps: 2 s² dt at every frequency; a sinusoid of amplitude A:
    its power A²/2 integrates under its peak; off a grid the classical periodogram has the same level."""
    from vibinverse.report import psd

    rng = np.random.default_rng(4)
    dt, n = 0.01, 20000
    t = np.arange(n) * dt
    y = rng.normal(scale=2.0, size=n)
    y[rng.random(n) < 0.3] = np.nan
    f, p = psd(t, y)
    assert np.mean(p) == pytest.approx(2 * 4.0 * dt, rel=0.03)
    line = 3.0 * np.sin(2 * np.pi * 12.5 * t) + rng.normal(scale=0.1, size=n)
    f, p = psd(t, line)
    assert np.sum(p) * (f[1] - f[0]) == pytest.approx(4.5 + 0.01, rel=0.03)
    tj = np.sort(rng.uniform(0, 20, 2000))
    f, p = psd(tj, rng.normal(scale=2.0, size=tj.size))
    assert np.mean(p) == pytest.approx(2 * 4.0 * 20 / 2000, rel=0.1)


def test_fold_recovers_a_sinusoid():
    from vibinverse.report import fold

    t = np.arange(5000) * 0.01
    c, m, _, k = fold(t, np.cos(2 * np.pi * 7.0 * t), 7.0, bins=20)
    assert np.allclose(m, np.cos(2 * np.pi * c), atol=0.1) and k.sum() == 5000


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
    assert "the data give only x < 0.0015 (90 %); below that the prior decides" in cut[0]
    # the sensor noise of a one-hour record without any: flat in log sigma down to the prior's 1e-8
    # (its median 1.27 in ln from the bound, more than half the interval's 2.31: the older rule missed it)
    noise = warnings_for(summary(3.57e-8, 1.14e-8, 1.15e-7, "loguniform(1e-08, 1000)", [1e-8, 1e3]), None, ["x"])
    assert len(noise) == 1 and "only x < 1.15e-07 (90 %)" in noise[0]
    high = warnings_for(summary(0.97, 0.75, 0.995, "uniform(0, 1)", [0.0, 1.0]), None, ["x"])
    assert len(high) == 1 and "only x > 0.75 (90 %); above that the prior decides" in high[0]
    inside = warnings_for(summary(0.4, 0.3, 0.5, "uniform(0, 1)", [0.0, 1.0]), None, ["x"])  # 4 sd from 0
    assert inside == []
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


def test_the_report_names_the_chosen_terms_and_why():
    from vibinverse.report import terms_html

    rows = [
        {"step": 0, "tried": "the scene's model", "terms": "white noise", "delta_bic": None, "kept": True},
        {
            "step": 1,
            "tried": "AR(1) noise added",
            "terms": "AR(1) noise, white noise",
            "delta_bic": -373.3,
            "kept": True,
        },
        {"step": 1, "tried": "random-walk drift added", "terms": "random-walk drift", "delta_bic": 8.3, "kept": False},
    ]
    summary = {"diagnostics": {"nuisance_search": rows}, "data": {"model": {"terms": "AR(1) noise, white noise"}}}
    html = terms_html(summary)
    assert "Model terms" in html and "<b>AR(1) noise, white noise</b>" in html
    assert "-373.3" in html and "+8.3" in html and html.count("kept") >= 2
    assert terms_html({"diagnostics": {}, "data": {}}) == ""


@pytest.mark.parametrize("rows, cols", [(1, 64), (8, 8), (3, 40)])
def test_the_gain_map_of_a_row_of_pixels_fills_its_panel(rows, cols):
    """The joint pixel fit's gain-and-sign map: a row of pixels was drawn as a thin strip inside an
    empty frame (issue 45); a long box is stretched to fill its panel, a square one drawn square.
    The saturated red and blue of the gains cover a good part of the figure either way."""
    import base64
    from pathlib import Path

    from PIL import Image

    from vibinverse.report import pixels_figure

    ys, xs = np.divmod(np.arange(rows * cols), cols)
    gains = np.where((ys + xs) % 2 == 0, 1.0, -1.0)
    summary = {
        "data": {"pixels": {"y": ys.tolist(), "x": xs.tolist(), "gain": gains.tolist()}},
        "diagnostics": {"n_pixels": rows * cols, "effective_snr_gain": 5.0},
    }
    title, png, _ = pixels_figure(summary, Path("."))
    rgb = np.asarray(Image.open(io.BytesIO(base64.b64decode(png.split(",", 1)[1]))).convert("RGB"), dtype=float)
    saturated = (np.abs(rgb[..., 0] - rgb[..., 2]) > 60).mean()  # red or blue, not grey or white
    assert title == "Pixels" and saturated > 0.25, saturated


def test_a_broad_hump_is_explained_not_reported_as_undetected():
    """A mode too damped to be a resonance (`mode_0_broad`) gets the broad hump's warning, not the
    "No ... is detected" one its `_detected` False would give otherwise."""
    from vibinverse.report import warnings_for

    d = {"mode_0_detected": False, "mode_0_broad": True, "mode_0_delta_loglike": 900.0, "mode_0_threshold": 20.0}
    out = warnings_for({"diagnostics": d, "parameters": {}}, None, [])
    assert len(out) == 1 and "mode 0 is a broad hump (damping ratio above 0.2" in out[0]
    d["mode_0_broad"] = False
    assert warnings_for({"diagnostics": d, "parameters": {}}, None, [])[0].startswith("No mode 0 is detected")


def test_a_product_of_stronger_tones_is_explained():
    from vibinverse.report import warnings_for

    d = {"line_3_detected": False, "line_3_product": "120 + 2 x 100 Hz", "line_3_delta_loglike": 5668.0}
    out = warnings_for({"diagnostics": d, "parameters": {}}, None, [])
    assert len(out) == 1 and "line 3 lies within a Fourier bin of 120 + 2 x 100 Hz" in out[0]


def test_a_figure_whose_drawing_process_hangs_is_drawn_here(monkeypatch):
    """`drawn_elsewhere`: a forked child that gives nothing within FIGURE_WAIT is killed and the
    figure drawn in the parent (a child stuck after a fork left CI's report tests waiting for good)."""
    import time

    from vibinverse import report as report_module

    monkeypatch.setattr(report_module, "FIGURE_WAIT", 0.5)
    parent = os.getpid()

    def render() -> str:
        if os.getpid() != parent:  # the child hangs
            time.sleep(60)
        return "drawn"

    start = time.perf_counter()
    assert report_module.drawn_elsewhere(render)() == "drawn"
    assert time.perf_counter() - start < 10

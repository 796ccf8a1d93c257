"""The robustness bench: its metrics count what they say, ours reads a modal summary, and a
reduced run goes end to end."""

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vibinverse.bench import robustness_bench as rb
from vibinverse.bench import robustness_fit as rf

# ------------------------------------------------------------------ the metrics


def test_match_is_a_hungarian_assignment_within_the_tolerance():
    assert rb.match([1.6, 2.1, 2.7], [2.72, 1.59, 5.0, 2.12]) == [1, 3, 0]
    assert rb.match([2.1, 2.2], [2.15]) == [None, 0]  # 2.15 is nearer 2.2 (relative)
    assert rb.match([2.0], [2.3]) == [None]  # 15 % away: missed
    assert rb.match([3.46], []) == [None]
    assert rb.match([], [1.0]) == []


def _truth(modes=((3.46, 0.014),), lines=((10.0, 0.15),)):
    return {
        "modes": [{"frequency": f, "damping_ratio": z, "rms": 0.3} for f, z in modes],
        "lines": [{"frequency": f, "amplitude": a, "phase": 0.0} for f, a in lines],
    }


def test_score_counts_coverage_misses_detections_and_failures():
    good = rf.FitOutcome(
        frequencies=[3.5],
        damping_ratios=[0.02],
        line_frequencies=[10.001],
        line_amplitudes=[0.12],
        intervals={"modes[0].frequency": (3.4, 3.6), "modes[0].damping_ratio": (0.012, 0.03)},
        lines_detected=[True],
        modes_detected=[True],
        seconds=1.0,
    )
    # the line fitted but not detected; the mode's interval misses; a spurious detected mode
    weak = rf.FitOutcome(
        frequencies=[3.45, 7.0],
        damping_ratios=[0.014, 0.1],
        line_frequencies=[10.0],
        line_amplitudes=[0.15],
        intervals={"modes[0].frequency": (3.30, 3.40)},
        lines_detected=[False],
        modes_detected=[True, True],
        seconds=3.0,
    )
    # the mode missed (fitted 20 % away), the line found
    miss = rf.FitOutcome(
        frequencies=[4.2], damping_ratios=[0.01], line_frequencies=[10.0], line_amplitudes=[0.15], seconds=2.0
    )
    failed = rf.FitOutcome(seconds=4.0, failed=True, note="boom")
    rows = rb.score("clean", "m", [_truth()] * 4, [good, weak, miss, failed])
    by = {r["param"]: r for r in rows}
    assert set(by) == {"mode frequency", "mode damping", "line frequency", "line amplitude"}
    f = by["mode frequency"]
    assert f["n"] == 4 and f["n_failed"] == 1 and f["n_missed"] == 1
    assert f["coverage90"] == 0.5 and f["n_intervals"] == 2
    assert f["coverage_se"] == pytest.approx(math.sqrt(0.25 / 2))
    assert f["median_rel_error"] == pytest.approx(np.median([0.04 / 3.46, 0.01 / 3.46]))
    assert by["mode damping"]["coverage90"] == 1.0 and by["mode damping"]["n_intervals"] == 1
    assert by["mode damping"]["median_rel_error"] == pytest.approx(np.median([0.006 / 0.014, 0.0]))
    assert by["line amplitude"]["median_rel_error"] == pytest.approx(np.median([0.2, 0.0, 0.0]))
    assert by["line frequency"]["coverage90"] is None
    assert f["line_detection"] == pytest.approx(2 / 3)  # detected, not detected, detected
    # the spurious detected 7 Hz mode; a mode missed at 4.2 Hz is itself spurious (nothing there)
    assert f["false_detection"] == pytest.approx(2 / 3)
    assert f["seconds"] == pytest.approx(2.5)
    # how the two intervals miss: the truth 0.66 of its sd from (3.4, 3.6)'s centre; 3.62 sd from
    # (3.30, 3.40)'s, beyond twice the 90 % half-width
    z = [(3.46 - 3.5) / (0.1 / rb.Z90), (3.46 - 3.35) / (0.05 / rb.Z90)]
    assert f["z_robust_sd"] == pytest.approx(rb.Z_MAD * np.median(np.abs(z)))
    assert f["far_miss"] == 0.5
    assert by["line frequency"]["z_robust_sd"] is None and by["line frequency"]["far_miss"] is None
    json.dumps(rows)


@settings(max_examples=60, deadline=None)
@given(
    true=st.floats(-10.0, 10.0),
    lo=st.floats(-10.0, 10.0),
    width=st.floats(1e-3, 10.0),
)
def test_interval_z_is_within_z90_exactly_when_the_interval_holds_the_truth(true, lo, width):
    hi = lo + width
    z = rb.interval_z(true, (lo, hi))
    if abs(abs(z) - rb.Z90) > 1e-9 * (1.0 + abs(z)):  # away from the edge, where rounding decides
        assert (abs(z) <= rb.Z90) == (lo <= true <= hi)


def test_interval_z_of_gaussian_posteriors_is_standard_normal():
    # estimates scattered by sd 1 around the truth, each with the right 90 % interval (+-Z90): the
    # z are the scatter itself, robust sd 1 (se ~ 1.1/sqrt(n) = 0.016 at n = 5000), far misses 0.1 %
    rng = np.random.default_rng(0)
    est = rng.standard_normal(5000)
    truths = [{"modes": [{"frequency": 3.0, "damping_ratio": 0.01}], "lines": []}] * est.size
    outs = [
        rf.FitOutcome(
            frequencies=[3.0 + 0.01 * e],
            damping_ratios=[0.01],
            intervals={"modes[0].frequency": (3.0 + 0.01 * (e - rb.Z90), 3.0 + 0.01 * (e + rb.Z90))},
        )
        for e in est
    ]
    f = {r["param"]: r for r in rb.score("clean", "m", truths, outs)}["mode frequency"]
    assert f["coverage90"] == pytest.approx(0.90, abs=0.013)  # 3 binomial se at n = 5000
    assert f["z_robust_sd"] == pytest.approx(1.0, abs=0.05)
    assert f["far_miss"] < 0.004


def test_score_noise_only_counts_any_detection_as_false():
    quiet = rf.FitOutcome(frequencies=[5.0], damping_ratios=[0.1], modes_detected=[False], seconds=1)
    loud = rf.FitOutcome(line_frequencies=[3.0], line_amplitudes=[0.1], lines_detected=[True], seconds=1)
    claims = rf.FitOutcome(frequencies=[5.0], damping_ratios=[0.1], seconds=1)  # no test: a claim
    rows = rb.score("noise_only", "m", [_truth((), ())] * 3, [quiet, loud, claims])
    assert len(rows) == 1 and rows[0]["param"] == "-"
    assert rows[0]["false_detection"] == pytest.approx(2 / 3)
    assert rows[0]["line_detection"] is None and rows[0]["median_rel_error"] is None


def test_outcome_from_a_modal_summary():
    p = lambda m, lo=None, hi=None: {"median": m, "q05": lo, "q95": hi}
    summary = {
        "parameters": {
            "modes[0].frequency": p(3.4, 3.3, 3.5),
            "modes[0].damping_ratio": p(0.01, 0.005, 0.02),
            "modes[1].frequency": p(5.0),
            "modes[1].damping_ratio": p(0.1),
            "lines[0].frequency": p(10.0, 9.99, 10.01),
            "lines[0].amplitude": p(0.15, 0.1, 0.2),
            "noise.sigma": p(0.6, 0.5, 0.7),
        },
        "diagnostics": {"mode_0_detected": True, "mode_1_detected": False, "line_0_detected": True},
    }
    o = rf.outcome_from_summary(summary)
    assert o.frequencies == [3.4, 5.0] and o.damping_ratios == [0.01, 0.1]
    assert o.modes_detected == [True, False] and o.lines_detected == [True]
    assert o.line_frequencies == [10.0] and o.line_amplitudes == [0.15]
    assert o.intervals["modes[0].frequency"] == (3.3, 3.5) and "modes[1].frequency" not in o.intervals
    assert "noise.sigma" not in o.intervals
    assert o.posterior == "emcee"  # no approximation named: the intervals are of emcee's draws
    assert rf.outcome_from_summary({**summary, "approximation": "importance"}).posterior == "importance"
    # a resonance whose values depend on an undecided line: the union of the two readings' intervals
    summary["diagnostics"]["ambiguous"] = [
        {"alternative": "a line", "intervals": {"modes[0].frequency": [3.2, 3.45], "lines[1].frequency": [4, 4.1]}},
        {"alternative": "a resonance read as a line"},  # no intervals: nothing to add
    ]
    o = rf.outcome_from_summary(summary)
    assert o.intervals["modes[0].frequency"] == (3.2, 3.5) and o.intervals["modes[0].damping_ratio"] == (0.005, 0.02)
    assert "lines[1].frequency" not in o.intervals  # another reading's line: not this fit's


def test_score_reports_the_oracle_rates_of_each_kind():
    """oracle_detection counts every data set's components of the row's kind, failed fits included."""
    o = lambda kind, d, k: {"kind": kind, "detected": d, "detected_known": k}
    truths = [
        {**_truth(), "oracle": [o("modes", True, True), o("lines", False, True)]},
        {**_truth(), "oracle": [o("modes", False, True), o("lines", False, False)]},
    ]
    fits = [rf.FitOutcome(frequencies=[3.46], damping_ratios=[0.014], seconds=1), rf.FitOutcome(failed=True)]
    by = {r["param"]: r for r in rb.score("clean", "m", truths, fits)}
    assert by["mode damping"]["oracle_detection"] == 0.5 and by["mode damping"]["oracle_known_frequency"] == 1.0
    assert by["line amplitude"]["oracle_detection"] == 0.0 and by["line amplitude"]["oracle_known_frequency"] == 0.5
    assert by["mode frequency"]["found"] == 1.0 and by["line frequency"]["found"] == 0.0
    assert by["mode frequency"]["oracle_refit_detection"] is None  # no refitted gains
    truths[0]["oracle"][0]["detected_refit"] = True  # one refitted: the rate over that one
    assert rb.score("clean", "m", truths, fits)[0]["oracle_refit_detection"] == 1.0
    assert rb.score("clean", "m", [_truth()], fits[:1])[0]["oracle_detection"] is None  # no oracle: None


# ------------------------------------------------------------------ the run


class _Fake:
    """A fitter that reports the truth of the clean case (with a 1 % error), for the harness."""

    name = "fake"

    def fit(self, t, y, order=None):
        k, m = order
        return rf.FitOutcome(
            frequencies=[3.5] * k,
            damping_ratios=[0.014] * k,
            line_frequencies=[10.0] * m,
            line_amplitudes=[0.15] * m,
            intervals={"modes[0].frequency": (3.4, 3.6)} if k else {},
            lines_detected=[True] * m,
            modes_detected=[True] * k,
            seconds=0.01,
        )


def test_run_table_and_plot_with_a_hand_made_fitter(tmp_path):
    res = rb.run(quick=True, n=2, cases=["clean", "noise_only"], fitters=[_Fake()], workers=1, log=lambda *a: None)
    json.dumps(res)
    rows = {(r["case"], r["param"]): r for r in res["rows"]}
    # every fit kept: case, seed, method, truth and outcome
    assert [(f["case"], f["seed"], f["method"]) for f in res["fits"]] == [
        ("clean", 0, "fake"),
        ("clean", 1, "fake"),
        ("noise_only", 0, "fake"),
        ("noise_only", 1, "fake"),
    ]
    assert res["fits"][0]["outcome"]["frequencies"] == [3.5] and res["fits"][0]["truth"]["case"] == "clean"
    assert rows["clean", "mode frequency"]["coverage90"] == 1.0
    assert rows["clean", "mode frequency"]["median_rel_error"] == pytest.approx(0.0359 / 3.4641, rel=0.02)
    assert rows["clean", "line amplitude"]["line_detection"] == 1.0
    assert rows["noise_only", "-"]["false_detection"] == 1.0  # it claims the clean case's components
    # the oracle: the clean 10 s resonance gains ~200 in log-likelihood at the truth, 10x its threshold
    assert rows["clean", "mode damping"]["oracle_detection"] == 1.0 and rows["clean", "mode frequency"]["found"] == 1.0
    assert rows["clean", "line frequency"]["oracle_known_frequency"] is not None
    assert rows["clean", "line frequency"]["oracle_refit_detection"] is not None
    assert rows["noise_only", "-"]["oracle_detection"] is None and res["settings"]["oracle"] is True
    assert res["settings"]["durations_s"] == {"clean": 10.0, "noise_only": 10.0}
    text = rb.table(res)
    assert text.splitlines()[0].split()[:3] == ["case", "method", "parameter"]
    assert {"found", "oracle", "or_kf", "or_rf"} <= set(text.splitlines()[0].split())
    assert len(text.splitlines()) == 1 + len(res["rows"])
    rb.plot(res["rows"], tmp_path / "robustness.png")
    assert (tmp_path / "robustness.png").read_bytes()[:4] == b"\x89PNG"


class _Mixed(_Fake):
    """The fake fitter whose odd seeds' intervals came from emcee (an importance check that failed)."""

    name = "mixed"
    calls = 0

    def fit(self, t, y, order=None):
        out = super().fit(t, y, order)
        out.posterior = "emcee" if self.calls % 2 else "importance"
        self.calls += 1
        return out


def test_run_notes_where_the_intervals_came_from_two_estimators():
    res = rb.run(
        quick=True, n=3, cases=["clean"], fitters=[_Fake(), _Mixed()], workers=1, log=lambda *a: None, with_oracle=False
    )
    assert "mixed on clean: intervals by importance in 2, emcee in 1" in res["notes"]
    assert not any(n.startswith("fake") for n in res["notes"])  # one kind (none named): nothing to note
    assert [f["outcome"]["posterior"] for f in res["fits"] if f["method"] == "mixed"] == [
        "importance",
        "emcee",
        "importance",
    ]
    assert res["settings"]["method_ours"] == "auto"  # ours as a user fits: the default method


def test_run_without_the_oracle_leaves_its_columns_empty():
    res = rb.run(
        quick=True, n=1, cases=["weak_drive"], fitters=[_Fake()], workers=1, log=lambda *a: None, with_oracle=False
    )
    assert all(r["oracle_detection"] is None and r["oracle_refit_detection"] is None for r in res["rows"])


def test_ours_fits_by_the_method_asked_and_ours_fixed_by_map():
    fl, _ = rb.available_fitters(["ours", "ours-fixed"], method="auto")
    assert [(f.name, f.method) for f in fl] == [("ours", "auto"), ("ours-fixed", "map")]


def test_unknown_names_are_refused():
    with pytest.raises(ValueError, match="case"):
        rb.run(cases=["nope"], fitters=[_Fake()], log=lambda *a: None)
    with pytest.raises(ValueError, match="fitter"):
        rb.available_fitters(["nope"])


@pytest.mark.slow
def test_quick_run_end_to_end_with_the_available_fitters(tmp_path):
    """`run(quick=True, cases=["clean"], n=2)` with every fitter that can run here (ours once the
    modal model is there, celerite2, SSI-cov); the others are listed as skipped."""
    res = rb.run(quick=True, n=2, cases=["clean"], workers=1, log=lambda *a: None)
    methods = {r["method"] for r in res["rows"]}
    assert methods | set(res["skipped"]) == set(rb.QUICK_FITTERS)
    for r in res["rows"]:
        assert r["n"] == 2 and r["seconds"] > 0
    freq = {r["method"]: r for r in res["rows"] if r["param"] == "mode frequency"}
    for m in methods & {"ours", "celerite2"}:
        assert freq[m]["n_failed"] == 0 and freq[m]["median_rel_error"] < 0.05
    json.dumps(res)
    rb.plot(res["rows"], tmp_path / "r.png")

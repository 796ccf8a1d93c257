"""`bench --realdata`: the corpus loader on the real cases.json, the scoring on hand-made claims,
the missing-corpus error, and one real case end to end."""

import os
from pathlib import Path

import pytest

from tests.conftest import run_cli
from vibinverse.bench import realdata_bench as rb
from vibinverse.bench import realdata_cases as rc
from vibinverse.bench.limited_processes import StepResult
from vibinverse.errors import InputError

CORPUS = Path(__file__).resolve().parents[3].parent / "shared" / "realdata-dev"
needs_corpus = pytest.mark.skipif(
    not (CORPUS / "cases.json").is_file(), reason=f"the real-data corpus is not at {CORPUS}"
)


def _ref(value, tol=None, scored=True, name=None, band=None, present=None):
    return rc.Reference(name or f"{value:g} Hz", value, "line", tol, scored, present, band)


# ------------------------------------------------------------------------------------ the corpus
@needs_corpus
def test_the_loader_reads_the_eight_cases_their_files_and_references():
    cases = {c.id: c for c in rc.load_cases(CORPUS)}
    assert len(cases) == 8
    for hz in (32, 64, 128):
        fork = cases[f"tuningfork_{hz}hz_video"]
        assert fork.kind == rc.VIDEO
        assert [f.true_fps for f in fork.files] == [250, 500, 1000]  # the true rates, not the container's 50
        assert [f.label for f in fork.files] == ["fps250", "fps500", "fps1000"]
        assert all(f.path.suffix == ".mp4" and f.path.is_file() for f in fork.files)  # no ffprobe JSON, no ROI
        assert all(0.55 < f.tolerance_hz < 0.65 for f in fork.files)  # max(2/T, 0.5 % of f)
    alias = cases["tuningfork_128hz_video"].files[0]
    assert alias.aliased and alias.expected_apparent_hz == 122 and rb.fold(128.0, alias.true_fps) == 122
    ligo = cases["ligo_h1_gw150914_lines"]
    assert ligo.kind == rc.SERIES and ligo.tolerance_hz == 0.1
    scored = [r.value_hz for r in ligo.references if r.scored]
    context = [r.value_hz for r in ligo.references if not r.scored]
    assert scored == [36.7, 331.9, 1083.7, 60.0] and context == [35.9, 504.8]
    assert ligo.files[0].series.channel == "strain"
    beam = cases["beam_shaker_drive_tones"]
    assert [r.value_hz for r in beam.references if r.scored] == [100.0, 120.0, 150.0]
    assert {r.value_hz for r in beam.references if not r.scored} == {6.64, 41.34, 117.5}  # values_hz, context
    assert all(r.in_file("data_set_3_downsampled_by_16.lvm") for r in beam.references)
    plate = cases["plate_sweep_force_acc"]
    assert plate.references[0].tolerance_hz == 1.5 and len(plate.files) == 5 and plate.expected_failure
    slab = cases["slab_smartphone_walking"].files[0].series
    assert slab.skip == 2000 and slab.time_column == "Time (s)"
    assert rc.select(list(cases.values()), ["slab_smartphone_walking"])[0].id == "slab_smartphone_walking"
    with pytest.raises(InputError, match="--cases: 'nope'; allowed: tuningfork_32hz_video"):
        rc.select(list(cases.values()), ["nope"])


@needs_corpus
def test_the_quick_form_takes_the_250_fps_take_and_one_file_per_series_case():
    cases = {c.id: c for c in rc.load_cases(CORPUS)}
    assert [f.true_fps for f in rb.quick_files(cases["tuningfork_64hz_video"])] == [250]
    assert [f.label for f in rb.quick_files(cases["plate_sweep_force_acc"])] == ["view_0"]


def test_a_missing_corpus_is_one_line_naming_the_path_and_the_variable(monkeypatch, tmp_path):
    monkeypatch.setenv(rc.ENV, str(tmp_path / "nowhere"))
    with pytest.raises(InputError) as info:
        rc.corpus_dir()
    text = str(info.value)
    assert "\n" not in text and str(tmp_path / "nowhere") in text and rc.ENV in text


def test_the_corpus_defaults_to_shared_beside_the_repository(monkeypatch):
    monkeypatch.delenv(rc.ENV, raising=False)
    root = rc.repo_root()
    assert (root / "pyproject.toml").is_file()
    if (CORPUS / "cases.json").is_file():
        assert rc.corpus_dir() == root.parent / "shared" / "realdata-dev"


@needs_corpus
def test_every_series_case_is_read_by_load_series():
    cases = {c.id: c for c in rc.load_cases(CORPUS)}
    for cid, n, span in (
        ("slab_smartphone_walking", 25291 - 2000, None),  # the first 2000 samples dropped
        ("beam_shaker_drive_tones", 63041, 19.7),
        ("plate_sweep_force_acc", 51200, 2.0),
        ("ligo_h1_gw150914_lines", 131072, 32.0),
        ("footbridge_impulse_3ch", 88800, 12.14),
    ):
        for f in cases[cid].files[:1]:
            series, how = rb.read_series(f.path, f.series)
            assert how == "load_series" and series.time.size == n
            if span is not None:
                assert series.time[-1] - series.time[0] == pytest.approx(span, abs=0.01)


# ------------------------------------------------------------------------------------ the scoring
def test_fold_gives_the_apparent_frequency():
    assert rb.fold(128.0, 250.0) == pytest.approx(122.0)
    assert rb.fold(32.0, 250.0) == 32.0
    assert rb.fold(256.0, 250.0) == pytest.approx(6.0)
    assert rb.fold(1083.7, 4096.0) == pytest.approx(1083.7)
    assert rb.fold(5.0, None) == 5.0


def test_a_claim_within_the_tolerance_finds_the_reference_and_one_outside_is_spurious():
    claims = [rb.Claim(32.3, "fit", "modes[0]"), rb.Claim(40.0, "fit", "lines[0]")]
    s = rb.score(claims, [_ref(32.0)], fs=250.0, tolerance=0.56)
    assert s.found == ["32"] and s.total == 1 and not s.missed
    assert s.spurious == [40.0]
    assert [c.verdict for c in claims] == ["found", "spurious"]


def test_harmonics_sums_and_differences_explain_claims():
    refs = [_ref(100.0), _ref(120.0)]
    claims = [rb.Claim(f, "fit", f"c{f}") for f in (200.0, 360.0, 220.0, 20.0, 777.0)]
    s = rb.score(claims, refs, fs=3200.0, tolerance=0.1)
    assert [c.verdict for c in claims] == ["explained"] * 4 + ["spurious"]
    assert [c.explained_by for c in claims[:4]] == ["2x100", "3x120", "100+120", "120-100"]
    assert s.spurious == [777.0] and s.missed == ["100", "120"]  # an explained claim finds nothing


def test_harmonic_8_explains_and_9_does_not():
    claims = [rb.Claim(8 * 10.0, "fit", "a"), rb.Claim(9 * 10.0, "fit", "b")]
    rb.score(claims, [_ref(10.0)], fs=1000.0, tolerance=0.1)
    assert [c.verdict for c in claims] == ["explained", "spurious"]


def test_aliased_references_and_harmonics_are_folded_at_the_sampling_rate():
    # the 128 Hz fork at 250 fps: seen at 122 Hz; its 2nd harmonic (256 Hz) at 6 Hz
    claims = [rb.Claim(122.1, "detect", "line 0"), rb.Claim(6.1, "detect", "line 1"), rb.Claim(128.0, "detect", "l2")]
    s = rb.score(claims, [_ref(128.0)], fs=250.0, tolerance=0.61)
    assert [c.verdict for c in claims] == ["found", "explained", "spurious"]  # 128 cannot be seen at 250 fps
    assert claims[0].reference_hz == pytest.approx(122.0) and claims[1].explained_by == "2x128"
    assert s.found == ["122"]


def test_context_references_explain_but_are_never_missed():
    refs = [_ref(36.7), _ref(35.9, scored=False), _ref(500.0, scored=False, band=(495.0, 515.0))]
    claims = [rb.Claim(35.92, "fit", "a"), rb.Claim(508.0, "fit", "b")]
    s = rb.score(claims, refs, fs=4096.0, tolerance=0.1)
    assert [c.verdict for c in claims] == ["context", "explained"]
    assert s.total == 1 and s.missed == ["36.7"] and not s.spurious


def test_claims_not_claimed_are_neither_found_nor_spurious():
    claims = [rb.Claim(32.0, "detect", "line 0", claimed=False, kind="scattered"), rb.Claim(50.0, "detect", "x", False)]
    s = rb.score(claims, [_ref(32.0)], fs=250.0, tolerance=0.5)
    assert s.found == [] and s.spurious == [] and {c.verdict for c in claims} == {"not claimed"}


def test_the_explanation_widens_to_two_fourier_bins():
    claim = [rb.Claim(65.5, "fit", "a")]
    rb.score(claim, [_ref(32.0)], fs=250.0, tolerance=0.5, duration_s=4.0)  # 2 bins = 0.5 Hz: not enough
    assert claim[0].verdict == "spurious"
    claim = [rb.Claim(65.5, "fit", "a")]
    rb.score(claim, [_ref(32.0)], fs=250.0, tolerance=0.5, duration_s=1.0)  # 2 bins = 2 Hz
    assert claim[0].verdict == "explained"


def test_coverage_counts_the_matching_claims_whose_interval_holds_the_reference():
    claims = [
        rb.Claim(32.1, "fit", "a", interval=(31.95, 32.2)),  # holds 32
        rb.Claim(60.02, "fit", "b", interval=(60.01, 60.03)),  # misses 60
        rb.Claim(36.7, "fit", "c"),  # no interval: not counted
        rb.Claim(80.0, "fit", "d", interval=(79.0, 81.0)),  # spurious: not counted
    ]
    s = rb.score(claims, [_ref(32.0, tol=0.5), _ref(60.0), _ref(36.7)], fs=1000.0, tolerance=0.1)
    assert (s.n_covered, s.n_intervals, s.coverage) == (1, 2, 0.5)
    assert [c.covered for c in claims] == [True, False, None, None]
    assert rb.score([], [_ref(1.0)], fs=10.0, tolerance=0.1).coverage is None


def test_a_modal_summary_gives_claims_with_intervals_and_detection():
    summary = {
        "parameters": {
            "modes[0].frequency": {"median": 17.86, "q05": 17.8, "q95": 17.9},
            "modes[0].damping_ratio": {"median": 0.01, "q05": 0.005, "q95": 0.02},
            "lines[0].frequency": {"median": 60.0, "q05": None, "q95": None},
            "lines[1].frequency": {"median": 120.0, "q05": 119.9, "q95": 120.1},
            "noise.sigma": {"median": 1.0, "q05": 0.9, "q95": 1.1},
        },
        "diagnostics": {"mode_0_detected": True, "line_1_detected": False},
    }
    claims = rb.claims_from_summary(summary)
    assert [(c.what, c.frequency, c.claimed, c.interval) for c in claims] == [
        ("modes[0]", 17.86, True, (17.8, 17.9)),
        ("lines[0]", 60.0, True, None),  # no test: claimed
        ("lines[1]", 120.0, False, (119.9, 120.1)),
    ]


def test_detection_lines_are_claimed_by_their_kind():
    from vibinverse.imaging.detection_map import Line

    plain = Line(0, 32.0, 32.0, 100.0, 1e-9, 50, (), alias_frequency=218.0)
    scattered = Line(1, 32.0, 32.0, 100.0, 1e-9, 3, (), kind="scattered", reason="3 pixels", alias_frequency=218.0)
    claims = rb.claims_from_lines([plain, scattered])
    assert [c.claimed for c in claims] == [True, False]
    assert claims[1].kind == "scattered" and "218" in claims[1].note


def test_a_row_without_an_answer_says_so_in_the_table_and_the_figure(tmp_path):
    case = rc.Case("x_case", rc.SERIES, (), (_ref(12.0),), 0.5)
    file = rc.CaseFile(Path("VI0.txt"), label="VI0")
    row = rb._row(case, file, "fit", StepResult("timeout", 60.0))
    result = {"rows": [row], "settings": {"fit_limit_s": 60}, "seconds": 61}
    text = rb.table(result)
    assert "x_case" in text and "-/1" in text and "no answer within 60 s" in text
    rb.plot(result, tmp_path / "realdata.png.part")  # as write_all names it before the rename
    assert (tmp_path / "realdata.png.part").read_bytes()[:4] == b"\x89PNG"


# ----------------------------------------------------------------------------------- end to end
@pytest.mark.slow
@needs_corpus
def test_the_250_fps_take_of_the_128_hz_fork_runs_end_to_end_and_finds_its_line(tmp_path, monkeypatch):
    """detect, then the joint fit of the strongest line's largest cluster, as the bench runs them:
    both steps finish and find the fork (at 250 fps it shows at its alias, 122 Hz). The 128 Hz take:
    its fit is the quick one (~16 s; the 32 Hz take's ~50 s)."""
    monkeypatch.setenv(rc.ENV, str(CORPUS))
    result = rb.run(quick=True, cases=["tuningfork_128hz_video"], workers=1)
    rows = result["rows"]
    assert [(r["case"], r["file"], r["stage"]) for r in rows] == [
        ("tuningfork_128hz_video", "fps250", "detect"),
        ("tuningfork_128hz_video", "fps250", "fit"),
    ]
    for r in rows:
        assert r["status"] == "ok" and len(r["found"]) == 1, (r["stage"], r["status_text"], r["found"])
    text = rb.table(result)
    assert "tuningfork_128hz_video" in text and "fps250" in text
    rb.plot(result, tmp_path / "realdata.png")
    assert (tmp_path / "realdata.png").stat().st_size > 5_000


def test_the_cli_refuses_cases_without_realdata_or_scene_and_unknown_cases(tmp_path, monkeypatch):
    r = run_cli("bench", "--cases", "a", "-o", str(tmp_path))
    assert r.returncode == 2 and "--cases" in r.stderr
    monkeypatch.setenv(rc.ENV, str(tmp_path / "nowhere"))
    r = run_cli("bench", "--realdata", "--cases", "a", "-o", str(tmp_path / "out"))
    assert r.returncode == 2 and rc.ENV in r.stderr
    if (CORPUS / "cases.json").is_file():
        monkeypatch.setenv(rc.ENV, str(CORPUS))
        r = run_cli("bench", "--realdata", "--cases", "nope", "-o", str(tmp_path / "out"))
        assert r.returncode == 2 and "'nope'" in r.stderr
    assert not (tmp_path / "out").exists()


def test_the_environment_variable_names_the_corpus(monkeypatch, tmp_path):
    (tmp_path / "cases.json").write_text('{"cases": []}')
    monkeypatch.setenv(rc.ENV, str(tmp_path))
    assert rc.corpus_dir() == tmp_path and rc.load_cases() == []
    assert os.environ[rc.ENV] == str(tmp_path)

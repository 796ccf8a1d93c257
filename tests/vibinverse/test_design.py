"""Design of observation: the paper's sec. 5 advice from reduced sweeps, Fisher oracles, and
bad sweep specifications."""

import itertools
import json
import math

import numpy as np
import pytest

from forward.scene_file import apply_overrides, read_table, scene_from_table
from forward.solar import sun_angles
from vibinverse.cli import main
from vibinverse.design.metrics import line_amplitude
from vibinverse.design.spec import configure, parse_vary
from vibinverse.design.sweep import run_design
from vibinverse.errors import VibinverseError
from vibinverse.io.builtin import builtin_scene

ROOF = "surfaces.roof.motion."
WAVELENGTH = 75.0  # ground scene: 3000 m/s at 40 Hz


def table(name: str, *overrides: str) -> dict:
    return apply_overrides(read_table(builtin_scene(name)), list(overrides))


def rows_by(result: dict, key: str) -> dict:
    return {r[key]: r for r in result["rows"]}


# ----------------------------------------------------------------------------- specifications


def test_vary_ranges_lists_and_categories():
    assert parse_vary("sensor.offset=-0.01:0.01:5").values == pytest.approx((-0.01, -0.005, 0.0, 0.005, 0.01))
    assert parse_vary("sun.inclination=pi/6").values == pytest.approx((math.pi / 6,))
    assert parse_vary("sampling.fs=100, 200,400").values == (100.0, 200.0, 400.0)
    assert parse_vary("sensor.polarizer=none,p,s").values == ("none", "p", "s")


@pytest.mark.parametrize(
    "spec, message",
    [
        ("sensor.offset=0:1:0", "empty range"),
        ("sensor.offset=", "empty range"),
        ("sensor.offset=0:1", "start:stop:num"),
        ("sensor.offset=0:1:x", "num must be an integer"),
        ("sampling.fs=fast,slow", "'fast' is not a number"),
        ("sensor.offset=1,,2", "empty item"),
        ("noequals", "expected dotted.key"),
    ],
)
def test_bad_specifications_name_the_problem(spec, message):
    with pytest.raises(VibinverseError, match=message):
        parse_vary(spec)


@pytest.mark.parametrize(
    "args, message",
    [
        (["--vary", "sensor.bogus=0:1:3"], "--vary sensor.bogus: sensor.bogus: unknown key"),
        (["--vary", "sensor.offset=0:0.01:0"], "empty range"),
        (["--vary", "sampling.fs=abc"], "'abc' is not a number"),
        (["--target", ROOF + "bogus"], "--target surfaces.roof.motion.bogus: no such scene value"),
        (["--threshold", "-1"], "--threshold"),
        (["--vary", "sensor.offset=0,0.01", "--vary", "sensor.offset=0.02"], "given twice"),
    ],
)
def test_cli_rejects_bad_sweeps_with_exit_2_and_no_output(tmp_path, capsys, args, message):
    out = tmp_path / "design"
    code = main(["design", str(builtin_scene("roof_elastic")), "-o", str(out), "--no-progress", *args])
    err = capsys.readouterr().err
    assert code == 2 and message in err and err.count("\n") == 1 and "Traceback" not in err
    assert not out.exists()


def test_design_keys_place_view_and_footprint():
    base = table("roof_elastic")
    scene = scene_from_table(configure(base, {"sensor.offset": 0.02, "footprint.center": 0.0}))
    assert scene.sensor.inclination == pytest.approx(scene.sun.inclination + 0.02)
    assert scene.sensor.azimuth == pytest.approx(scene.sun.azimuth + math.pi)
    assert scene.footprint.x == (-25.0, 25.0) and scene.footprint.y == (-25.0, 25.0)
    scene = scene_from_table(configure(base, {"footprint.width": 20.0}))
    assert scene.footprint.x == (0.0, 20.0) and scene.footprint.y == (0.0, 20.0)


# ----------------------------------------------------------------------------- sun position


def test_sun_position_equinox_noon_and_below_horizon():
    # at an equinox the noon sun stands 90 deg - |latitude| high (declination ~0; refraction < 0.1 deg)
    for lat in (0.0, 30.0, -45.0):
        best = max(sun_angles("2026-03-20", h, lat, 0.0)[0] for h in np.arange(11.9, 12.3, 0.01))
        assert math.degrees(best) == pytest.approx(90.0 - abs(lat), abs=0.6)
    # morning sun in the east: scene azimuth (from +x = east) near 0
    el, az = sun_angles("2026-03-20", 7.0, 0.0, 0.0)
    assert 0 < el < 0.5 and abs(az) < 0.1
    with pytest.raises(VibinverseError, match=r"sun\.hour: the sun is below the horizon"):
        sun_angles("2026-03-20", 0.0, 0.0, 0.0)


def test_hours_of_a_day_are_one_vary_away():
    base = table("ground_rayleigh", "noise.sigma=1e-6")
    del base["sun"]["inclination"], base["sun"]["azimuth"]
    base["sun"].update({"date": "2026-06-21", "latitude": 38.9, "longitude": -77.0, "utc_offset": -4})
    res = run_design(base, ["sun.hour=4:20:9"], None)
    by = rows_by(res, "sun.hour")
    assert "below the horizon" in by[4.0]["status"]  # before sunrise: a row that says why, not a crash
    ok = [h for h, r in by.items() if r["status"] == "ok"]
    assert len(ok) >= 6
    # diffuse ground: the low morning and evening sun beat noon
    assert by[6.0]["sensitivity"] > 10 * by[12.0]["sensitivity"]


# ----------------------------------------------------------------------------- the paper's sec. 5


@pytest.fixture(scope="module")
def roof_sweep():
    base = table("roof_elastic", "footprint.resolution=64")
    return run_design(base, ["sensor.offset=-0.03:0.03:25", "footprint.center=0,25"], None)


def test_quadrant_beats_centered(roof_sweep):
    for r0 in (r for r in roof_sweep["rows"] if r["footprint.center"] == 0.0 and abs(r["sensor.offset"]) >= 0.005):
        r1 = next(
            r for r in roof_sweep["rows"] if r["footprint.center"] == 25.0 and r["sensor.offset"] == r0["sensor.offset"]
        )
        assert r1["sensitivity"] > 100 * r0["sensitivity"]
        assert r1[f"crlb {ROOF}frequency"] < r0[f"crlb {ROOF}frequency"] / 10
    assert all(r["footprint.center"] == 25.0 for r in roof_sweep["best"][:4])


def test_specular_roof_best_view_is_off_the_lobe_centre(roof_sweep):
    best = roof_sweep["best"][0]
    # the sharpest parameters where the lobe is steepest, about one lobe width (0.01 rad) off centre;
    # the paper's ~0.015 rad
    assert 0.005 <= abs(best["sensor.offset"]) <= 0.02
    centre = next(r for r in roof_sweep["rows"] if r["footprint.center"] == 25.0 and r["sensor.offset"] == 0.0)
    assert centre[f"crlb {ROOF}frequency"] > 5 * best[f"crlb {ROOF}frequency"]
    assert centre["sensitivity"] < best["sensitivity"] / 10


def test_diffuse_ground_prefers_a_low_sun():
    res = run_design(
        table("ground_rayleigh", "noise.sigma=1e-6"), ["sun.inclination=0.01,0.05,0.1,0.15,0.2,0.3,0.5"], None
    )
    s = [r["sensitivity"] for r in res["rows"]]
    assert all(a > b for a, b in itertools.pairwise(s))
    by = rows_by(res, "sun.inclination")
    # detectable (paper's threshold 1e-4) below ~0.15 rad; ours reaches 0.22 rad with R = 10 m (README)
    assert by[0.15]["sensitivity"] > 1e-4 > by[0.3]["sensitivity"]
    assert res["best"][0]["sun.inclination"] == 0.01


def test_best_ground_footprint_is_a_fraction_of_the_wavelength():
    res = run_design(table("ground_rayleigh", "noise.sigma=1e-6"), ["footprint.width=5:50:19"], None)
    widths = [r["footprint.width"] for r in res["rows"]]
    s = [r["sensitivity"] for r in res["rows"]]
    best = widths[int(np.argmax(s))]
    assert 0.2 * WAVELENGTH <= best <= 0.4 * WAVELENGTH  # paper: lambda_R / 3; ours 0.25-0.27 lambda_R (README)
    first = rows_by(res, "footprint.width")[5.0]  # inside the piston (R = 10 m): no slope, nothing to see
    assert first["sensitivity"] == 0.0 and math.isinf(first["crlb surfaces.ground.motion.frequency"])


def test_p_polarizer_at_brewster_wins_for_glass_in_sensitivity_and_when_shot_noise_limited():
    by = rows_by(
        run_design(table("glass_brewster", "noise.photons_per_unit=1e6"), ["sensor.polarizer=none,p,s"], None),
        "sensor.polarizer",
    )
    assert by["p"]["sensitivity"] > 0.9 and by["none"]["sensitivity"] < 1e-4
    key = "rel_crlb surfaces.pane.motion.frequency"
    assert by["p"][key] < by["none"][key] / 2
    # with a fixed read noise the polarizer throws away the light: the ordering reverses (README)
    by = rows_by(
        run_design(table("glass_brewster", "noise.sigma=1e-3"), ["sensor.polarizer=none,p"], None), "sensor.polarizer"
    )
    assert by["p"][key] > 100 * by["none"][key]


# ----------------------------------------------------------------------------- Fisher oracles


def test_deterministic_crlb_equals_the_sinusoid_bound():
    """Rife & Boorstyn (1974): a real sinusoid of amplitude A in white noise sigma, N samples at fs,
    phase and level unknown: sd(f) = sqrt(24 sigma^2 / (A^2 N (N^2 - 1))) fs / (2 pi)."""
    base = table("roof_elastic", "footprint.resolution=64")
    res = run_design(base, ["sensor.offset=0.015"], [ROOF + "frequency"])
    r = res["rows"][0]
    from forward.reduce import compile_scene

    scene = scene_from_table(configure(base, {"sensor.offset": 0.015}))
    c = compile_scene(scene, force="taylor2")
    amp = line_amplitude(c.t, c.parts()[1], 40.0)
    n, fs, sigma = c.t.size, scene.sampling.fs, scene.noise.sigma
    bound = math.sqrt(24 * sigma**2 / (amp**2 * n * (n**2 - 1))) * fs / (2 * math.pi)
    assert r[f"crlb {ROOF}frequency"] == pytest.approx(bound, rel=0.01)  # the 2f line adds < 1e-4


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
    names = [ROOF + "tilt_frequency", ROOF + "tilt_damping_ratio", ROOF + "noise_rms", "noise.sigma"]
    values = dict(zip(names, (2 * math.sqrt(3), 0.0137832223855448, 1e-4, 0.6)))
    fm = mean_fisher(like, values, names)
    whittle = crlb_from_fisher(fm + covariance_fisher(like, values, names), names)
    exact = crlb_from_fisher(fm + covariance_fisher_dense(like, values, names), names)
    for n in names:  # 15 s is ~4.5 decay times of the tilt mode: Whittle's O(decay/duration) error
        assert whittle[n] == pytest.approx(exact[n], rel=0.2)


def test_crlb_matches_the_spread_of_least_squares_estimates():
    """50 simulated datasets fitted by least squares on the forward model: the empirical sd of the
    frequency estimate matches the design's Cramer-Rao sd (the estimator is efficient at this SNR).
    With 50 datasets the sample sd itself scatters by ~10 %, so 30 % is a 3-sigma band."""
    from scipy.optimize import least_squares

    from forward.reduce import compile_scene
    from forward.sensor import add_noise

    base = table("roof_elastic", "footprint.resolution=32", "sampling.duration=0.2", "noise.sigma=0.5")
    freq, defl = ROOF + "frequency", ROOF + "center_deflection"
    crlb = run_design(base, ["sensor.offset=0.01"], [freq, defl])["rows"][0][f"crlb {freq}"]
    scene0 = scene_from_table(configure(base, {"sensor.offset": 0.01}))
    cache: dict = {}

    def model(p):
        tab = configure(
            base, {"sensor.offset": 0.01, freq: p[0], defl: p[1] * 1e-3, "surfaces.roof.motion.phase": p[2]}
        )
        dc, ac = compile_scene(scene_from_table(tab), force="taylor2", shape_cache=cache).parts()
        return dc + p[3] + ac

    clean = model([40.0, 1.0, 0.0, 0.0])
    estimates = []
    for seed in range(50):
        y = add_noise(clean, scene0.noise, np.random.default_rng(seed))
        fit = least_squares(lambda p: model(p) - y, [40.0, 1.0, 0.0, 0.0], x_scale=[0.01, 0.01, 0.01, 0.01])
        estimates.append(fit.x[0])
    spread = float(np.std(estimates, ddof=1))
    assert spread == pytest.approx(crlb, rel=0.3)
    assert abs(np.mean(estimates) - 40.0) < 3 * crlb / math.sqrt(50) + 1e-9


def test_frame_design_reproduces_the_inverse_cores_numbers():
    res = run_design(table("roof_frame", "noise.sigma=0.6"), ["sensor.offset=0.01"], None)
    r = res["rows"][0]
    assert r["snr 10 Hz"] == pytest.approx(11.0, rel=0.05)  # the demo's "SNR ~10" setting
    assert r[f"crlb {ROOF}drive_frequency"] == pytest.approx(0.00251, rel=0.02)  # issue 6's CRB
    assert 0 < r[f"crlb {ROOF}tilt_frequency"] < 0.1 and r[f"crlb {ROOF}tilt_damping_ratio"] > 0


# ----------------------------------------------------------------------------- CLI and outputs


def test_cli_writes_csv_json_and_maps_and_workers_agree(tmp_path, capsys):
    args = [
        "design",
        str(builtin_scene("roof_elastic")),
        "--set",
        "footprint.resolution=32",
        "--vary",
        "sensor.offset=-0.02:0.02:5",
        "--vary",
        "footprint.center=0,25",
        "--no-progress",
    ]
    assert main([*args, "-o", str(tmp_path / "a")]) == 0
    assert main([*args, "-o", str(tmp_path / "b"), "--workers", "2"]) == 0
    assert "10 configurations" in capsys.readouterr().out
    doc = json.loads((tmp_path / "a" / "design.json").read_text())
    assert doc["n_configurations"] == 10 and doc["threshold"] == 1e-4 and len(doc["best"]) == 10
    assert doc["best"][0]["footprint.center"] == 25.0
    a = (tmp_path / "a" / "design.csv").read_text().splitlines()
    b = (tmp_path / "b" / "design.csv").read_text().splitlines()
    assert len(a) == 11 and a == b
    for png in ("design_sensitivity.png", "design_crlb.png"):
        assert (tmp_path / "a" / png).read_bytes()[:4] == b"\x89PNG"


def test_default_sweeps_suit_the_scene():
    from vibinverse.design.sweep import default_axes

    assert [a.key for a in default_axes(table("roof_elastic"))] == ["sensor.offset", "footprint.center"]
    assert [a.key for a in default_axes(table("ground_rayleigh"))] == ["sun.inclination", "footprint.width"]


def test_design_needs_noise():
    res = run_design(table("ground_rayleigh"), ["sun.inclination=0.1"], None)
    assert "design needs sensor noise" in res["rows"][0]["status"]


def test_dotted_keys_set_list_elements_like_get_value_reads_them():
    from vibinverse.scene_keys import get_value, set_value

    t = {"m": {"f": [1.0, 2.0], "x": 3.0}}
    set_value(t, "m.f[1]", 5.0)
    set_value(t, "m.f", 7.0)  # a plain key on a list is its first element, as get_value reads it
    set_value(t, "m.x", 4.0)
    assert t == {"m": {"f": [7.0, 5.0], "x": 4.0}} and get_value(t, "m.f") == 7.0
    with pytest.raises(VibinverseError, match=r"m.f\[2\]: index 2 is outside the list of 2 values"):
        set_value(t, "m.f[2]", 1.0)
    with pytest.raises(VibinverseError, match="x is a value, not a table"):
        set_value(t, "m.x.y", 1.0)

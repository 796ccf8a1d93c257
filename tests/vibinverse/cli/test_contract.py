"""The command line's contract, for all inputs (hypothesis) and for a corpus of bad files: exit 0
with a valid result, or exit 2 with one line on stderr and no traceback, within a time limit, and
no file left behind.

The `ci` profile (default) runs a bounded, derandomized number of examples; `HYPOTHESIS_PROFILE=long
pytest tests/vibinverse/cli/test_contract.py` runs many more (see tests/conftest.py)."""

import contextlib
import io
import json
import math
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.conftest import SCENES
from vibinverse.cli import main

CORPUS = Path(__file__).resolve().parents[2] / "corpus"
ROOF = str(SCENES / "roof_elastic.toml")
SMALL = ["--set", "footprint.resolution=16", "--set", "sampling.duration=0.05"]
TIME_LIMIT = 20.0  # seconds per command: a refusal is immediate, a small simulation or fit takes ~1 s


def call(*args: str) -> tuple[int, str, str, float]:
    """Run the CLI in this process: (exit code, stdout, stderr, seconds). Any exception that is not
    turned into an exit code escapes and fails the test (a traceback for the user)."""
    out, err = io.StringIO(), io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(args))
    return code, out.getvalue(), err.getvalue(), time.perf_counter() - t0


def assert_contract(code: int, err: str, seconds: float, outputs: list[Path], before: set[Path], folder: Path) -> None:
    assert seconds < TIME_LIMIT, f"{seconds:.1f} s"
    assert "Traceback" not in err, err
    left = set(folder.iterdir()) - before
    if code == 0:
        assert all(p.exists() and p.stat().st_size > 0 for p in outputs), outputs
    else:
        assert code == 2, (code, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("vibinverse: error: "), err
        assert not left, f"left behind: {sorted(p.name for p in left)}"
    assert not list(folder.rglob("*.part")), left  # no temporary file, in the output directories either


def _finite_csv(path: Path) -> None:
    data = np.loadtxt(
        path, delimiter=",", comments="#", skiprows=sum(1 for ln in path.open() if ln.startswith("#")) + 1
    )
    assert np.all(np.isfinite(data)), "a result with exit 0 must be finite"


# ---------------------------------------------------------------- scene values (simulate --set)

KEYS = [
    "sun.inclination",
    "sun.azimuth",
    "sun.irradiance",
    "sensor.inclination",
    "sensor.azimuth",
    "noise.sigma",
    "noise.photons_per_unit",
    "noise.adc_bits",
    "sampling.fs",
    "sampling.start",
    "footprint.x",
    "surfaces.roof.lobe_width",
    "surfaces.roof.motion.frequency",
    "surfaces.roof.motion.center_deflection",
    "surfaces.roof.motion.phase",
    "title",
]
NUMBERS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-1e3, 1e3),
    st.integers(-(2**70), 2**70),
    st.sampled_from([0, -0.0, 1e-300, 1e300, 5e-324]),
)
VALUES = st.one_of(
    NUMBERS.map(repr),
    st.lists(NUMBERS, max_size=3).map(lambda v: "[" + ", ".join(map(repr, v)) + "]"),
    st.text(max_size=30).map(json.dumps),
    st.sampled_from(["'pi/3'", "'1/0'", "'sqrt(-1)'", "'9**9**9'", "true", "{}", "'a\\nb'", "[[1]]"]),
)


@settings(deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(st.lists(st.tuples(st.sampled_from(KEYS), VALUES), min_size=1, max_size=3))
def test_simulate_with_any_scene_values_keeps_the_contract(tmp_path, overrides):
    folder = tmp_path / f"s{time.perf_counter_ns()}"
    folder.mkdir()
    out = folder / "sim"
    sets = [a for k, v in overrides for a in ("--set", f"{k}={v}")]
    code, _, err, seconds = call("simulate", ROOF, *SMALL, *sets, "--seed", "1", "-o", str(out))
    assert_contract(code, err, seconds, [out / "series.csv"], set(), folder)
    if code == 0:
        _finite_csv(out / "series.csv")


# ---------------------------------------------------------------- options


@settings(deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(
    seed=st.one_of(st.integers(-(2**40), 2**40), st.sampled_from(["x", "1.5", "", "nan"])),
    rtol=st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.sampled_from(["abc", "1e-400"])),
)
def test_simulate_options_keep_the_contract(tmp_path, seed, rtol):
    folder = tmp_path / f"o{time.perf_counter_ns()}"
    folder.mkdir()
    out = folder / "sim"
    code, _, err, seconds = call("simulate", ROOF, *SMALL, "--seed", str(seed), "--rtol", str(rtol), "-o", str(out))
    assert_contract(code, err, seconds, [out / "series.csv"], set(), folder)


# ---------------------------------------------------------------- data arrays (fit)

N = 64


@st.composite
def series(draw):
    """(time, intensity) with the ways real files go wrong: gaps, non-finite values, huge or tiny
    scales, constant values, repeated or decreasing stamps, too few samples."""
    n = draw(st.integers(0, N))
    t = np.arange(n) / 1000.0
    kind = draw(st.sampled_from(["noise", "constant", "huge", "tiny", "inf", "nan", "mixed"]))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    y = 287.0 + rng.normal(0.0, 0.05, n)
    if kind == "constant":
        y = np.full(n, draw(st.floats(-1e3, 1e3)))
    elif kind == "huge":
        y = y * 1e300
    elif kind == "tiny":
        y = y * 1e-300
    elif kind == "inf" and n:
        y[draw(st.integers(0, n - 1))] = draw(st.sampled_from([math.inf, -math.inf]))
    elif kind == "nan" and n:
        y[: draw(st.integers(0, n))] = math.nan
    elif kind == "mixed" and n > 2:
        t[draw(st.integers(1, n - 1))] = t[draw(st.integers(0, n - 2))]  # a repeated or backward stamp
    return t, y


@settings(deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(series())
def test_fit_of_any_series_keeps_the_contract(tmp_path, data):
    folder = tmp_path / f"f{time.perf_counter_ns()}"
    folder.mkdir()
    t, y = data
    path = folder / "data.csv"
    path.write_text("time,intensity\n" + "".join(f"{a!r},{b!r}\n" for a, b in zip(t, y)))
    before = set(folder.iterdir())
    nc, js = folder / "r" / "result.nc", folder / "r" / "summary.json"
    code, _, err, seconds = call(
        "fit", str(path), "--scene", ROOF, *SMALL, "--method", "spectral", "-o", str(nc.parent)
    )
    assert_contract(code, err, seconds, [nc, js], before, folder)
    if code == 0:
        summary = json.loads(js.read_text(), parse_constant=lambda c: pytest.fail(f"non-strict JSON token {c}"))
        assert all(v["median"] is None or math.isfinite(v["median"]) for v in summary["parameters"].values())


# ---------------------------------------------------------------- a corpus of bad files


@pytest.mark.parametrize("path", sorted(p for p in (CORPUS / "scenes").glob("*") if p.is_file()), ids=lambda p: p.name)
def test_bad_scene_files_are_one_line_errors(tmp_path, path):
    out = tmp_path / "sim"
    code, _, err, seconds = call("simulate", str(path), "-o", str(out))
    assert_contract(code, err, seconds, [out / "series.csv"], set(), tmp_path)
    assert code == 2


@pytest.mark.parametrize(
    "path", sorted(p for p in (CORPUS / "data").glob("*") if p.suffix != ".md"), ids=lambda p: p.name
)
def test_data_files_of_the_corpus_keep_the_contract(tmp_path, path):
    """bad_* files are refused with one line; the others may fit or be refused, never a traceback."""
    nc, js = tmp_path / "r" / "result.nc", tmp_path / "r" / "summary.json"
    code, _, err, seconds = call("fit", str(path), "--scene", ROOF, "--method", "spectral", "-o", str(nc.parent))
    assert_contract(code, err, seconds, [nc, js], set(), tmp_path)
    if path.name.startswith("bad_") or path.suffix == ".nc":
        assert code == 2

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


# ---------------------------------------------------------------- all ten verbs: bad options and bad files
#
# Every verb on bad input: exit 2, exactly one stderr line naming the field (and for a number its
# allowed range), nothing on stdout, no traceback, nothing created or changed under the folder.
# Refusals are immediate, so the CI examples are many; `-m slow` runs a larger randomized set.

SEED_BAD = st.one_of(st.integers(max_value=-1), st.integers(min_value=2**32))


def _ints_outside(lo: int, hi: int):
    return st.one_of(st.integers(max_value=lo - 1), st.integers(min_value=hi + 1))


def _reals_outside(lo: float, hi: float, lo_in: bool = False, hi_in: bool = False):
    """Finite numbers outside [lo, hi] (an excluded bound itself included), and NaN and infinities."""
    parts = [st.sampled_from([math.nan, math.inf, -math.inf])]
    if math.isfinite(lo):
        parts.append(st.floats(max_value=lo, allow_nan=False, allow_infinity=False, exclude_max=lo_in))
    if math.isfinite(hi):
        parts.append(st.floats(min_value=hi, allow_nan=False, allow_infinity=False, exclude_min=hi_in))
    return st.one_of(*parts)


MALFORMED = st.one_of(
    st.sampled_from(["", " ", "x", "1,2", "0x10", "1e", "--", "1..2", "¹", "1_0_", "\n", "1;rm -rf /"]),
    st.text(alphabet=st.characters(blacklist_categories=("Nd",)), min_size=1, max_size=8),
)
INTEGER_MALFORMED = st.one_of(MALFORMED, st.sampled_from(["1.5", "2e3", "nan", "inf", "1.0"]))

# verb -> (the arguments before the option, {option: strategy of bad values}); the positional
# arguments are never read (parsing refuses the option first)
_I, _R = _ints_outside, _reals_outside
OPTIONS = {
    "simulate": (
        ["simulate", "SCENE.toml"],
        {
            "--seed": st.one_of(SEED_BAD, INTEGER_MALFORMED),
            "--video-fps": st.one_of(_R(0, 1e6, hi_in=True), MALFORMED),
            "--rtol": st.one_of(_R(0, math.inf), MALFORMED),
        },
    ),
    "fit": (
        ["fit", "DATA.csv"],
        {
            "--seed": st.one_of(SEED_BAD, INTEGER_MALFORMED),
            "--max-steps": st.one_of(_I(1, 10_000_000), INTEGER_MALFORMED),
            "--workers": st.one_of(_I(1, 1024), INTEGER_MALFORMED),
            "--modes": st.one_of(_I(0, 6), INTEGER_MALFORMED),
            "--lines": st.one_of(_I(0, 6), INTEGER_MALFORMED),
            "--fs": st.one_of(_R(0, math.inf), MALFORMED),
            "--fps": st.one_of(_R(0, math.inf), MALFORMED),
            "--scale": st.one_of(_R(0, math.inf), MALFORMED),
            "--sources": st.one_of(_I(1, 1_000_000), INTEGER_MALFORMED),
            "--band": st.one_of(MALFORMED, st.sampled_from(["5:2", "-1:3", "nan:3", "1:inf", "3:3"])),
            "--reference": st.one_of(MALFORMED, st.sampled_from(["-1,2", "1", "1,2,3", "a,b"])),
        },
    ),
    "detect": (
        ["detect", "CUBE.npy"],
        {
            "--alpha": st.one_of(_R(0, 1), MALFORMED),
            "--max-lines": st.one_of(_I(1, 1000), INTEGER_MALFORMED),
            "--fps": st.one_of(_R(0, math.inf), MALFORMED),
            "--workers": st.one_of(_I(1, 1024), INTEGER_MALFORMED),
            "--memory": st.one_of(st.sampled_from(["0", "-1MB", "x", "1e400", "nan", "2PiB", "1e99"]), MALFORMED),
            "--band": st.one_of(MALFORMED, st.sampled_from(["5:2", "-1:3", "nan:", ":nan", "3:3"])),
        },
    ),
    "extract": (
        ["extract", "CUBE.npy"],
        {
            "--bin": st.one_of(_I(1, 1_000_000), INTEGER_MALFORMED),
            "--fps": st.one_of(_R(0, math.inf), MALFORMED),
            "--line-time": st.one_of(_R(0, math.inf, lo_in=True), MALFORMED),
            "--chunks": st.one_of(_I(1, 1_000_000), INTEGER_MALFORMED),
            "--roi": st.one_of(MALFORMED, st.sampled_from(["0:1", "1:0,0:1", "-1:2,0:1"])),
            "--frames": MALFORMED,
        },
    ),
    "init": (
        ["init", "--no-input"],
        {
            "--latitude": st.one_of(_R(-90, 90, True, True), MALFORMED),
            "--longitude": st.one_of(_R(-180, 180, True, True), MALFORMED),
            "--utc-offset": st.one_of(_R(-14, 14, True, True), MALFORMED),
            "--hour": st.one_of(_R(0, 24, True, True), MALFORMED),
            "--fs": st.one_of(_R(0, math.inf), MALFORMED),
            "--duration": st.one_of(_R(0, math.inf), MALFORMED),
            "--sun-inclination": st.one_of(_R(0, 90, hi_in=True), MALFORMED),
            "--view-inclination": st.one_of(_R(0, 90, hi_in=True), MALFORMED),
            "--lobe-width": st.one_of(_R(0, 0.5, hi_in=True), MALFORMED),
            "--damping-ratio": st.one_of(_R(0, 1, lo_in=True), MALFORMED),
            "--noise-sigma": st.one_of(_R(0, math.inf, lo_in=True), MALFORMED),
            "--resolution": st.one_of(st.integers(max_value=0), INTEGER_MALFORMED),
        },
    ),
    "design": (
        ["design", "SCENE.toml"],
        {
            "--threshold": st.one_of(_R(0, math.inf, lo_in=True), MALFORMED),
            "--pixels": st.one_of(_I(1, 1_000_000), INTEGER_MALFORMED),
            "--workers": st.one_of(_I(1, 1024), INTEGER_MALFORMED),
        },
    ),
    "bench": (["bench", "--realdata"], {"--workers": st.one_of(_I(1, 1024), INTEGER_MALFORMED)}),
    "demo": (["demo"], {"--seed": st.one_of(SEED_BAD, INTEGER_MALFORMED)}),
    "report": (["report", "RESULT.nc"], {"-o": st.just("")}),
    "study": (["study"], {"": st.sampled_from(["nope", "", "../x", "<script>"])}),
}


@st.composite
def bad_options(draw):
    """(verb, option, the command line): one bad value of one option of one verb."""
    verb = draw(st.sampled_from(sorted(OPTIONS)))
    head, options = OPTIONS[verb]
    option = draw(st.sampled_from(sorted(options)))
    value = draw(options[option])
    text = value if isinstance(value, str) else repr(value) if isinstance(value, float) else str(value)
    arg = [text] if not option else [f"{option}={text}"]  # --opt=-1: never read as an option
    return verb, option, [*head, *arg]


def _snapshot(folder: Path) -> dict[str, tuple[int, int]]:
    """Every path under `folder` with its size and mtime: what a refused run must leave as it was."""
    return {str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns) for p in sorted(folder.rglob("*"))}


def _refused(folder: Path, argv: list[str], field: str | None) -> str:
    """Run `argv` (with -o inside `folder`) and assert the refusal contract; the stderr line."""
    before = _snapshot(folder)
    has_output = any(a == "-o" or a.startswith("-o=") for a in argv)
    out = [] if has_output else ["-o", str(folder / "out")]
    code, stdout, err, seconds = call(*argv, *out)
    assert seconds < TIME_LIMIT, f"{seconds:.1f} s"
    assert "Traceback" not in err, err
    assert code == 2, (code, argv, err)
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("vibinverse: error: "), (argv, err)
    assert stdout == "", (argv, stdout)
    assert _snapshot(folder) == before, f"changed under the folder: {argv}"
    if field:
        assert field in lines[0], (field, lines[0])
    return lines[0]


def _check_bad_option(verb: str, option: str, argv: list[str]) -> None:
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        line = _refused(Path(tmp), argv, None)
        if any(f"{field}: file not found" in line for field in ("input", "data")):
            # the command's input file does not exist either: an option whose check needs the data
            # (a band against the Nyquist frequency; --modes 7-36, allowed for a multi-channel
            # table, not for one series) is refused after it, and naming it is right
            return
        if option.startswith("--"):
            assert option in line, (option, line)
        if option.startswith("--") and verb != "init":  # a number's line names its allowed range
            # ... or where the option applies (a cube fit's --reference given to a series fit)
            words = ("range", "invalid", "allowed", "expected one argument", "applies to")
            assert any(w in line for w in words), line


CONTRACT = {"deadline": None, "suppress_health_check": [HealthCheck.function_scoped_fixture, HealthCheck.too_slow]}


@settings(**CONTRACT, derandomize=True, max_examples=300)
@given(bad_options())
def test_every_verb_refuses_bad_options_in_one_line(case):
    _check_bad_option(*case)


@pytest.mark.slow
@settings(**CONTRACT, derandomize=False, max_examples=600)
@given(bad_options())
def test_every_verb_refuses_bad_options_in_one_line_randomized(case):
    _check_bad_option(*case)


# bad files: verb -> (the arguments with FILE for the bad file, the suffixes it is given)
FILE_VERBS = {
    "simulate": (["simulate", "FILE"], [".toml"]),
    "simulate --image": (["simulate", "FILE", "--image", "2,2"], [".toml"]),
    "design": (["design", "FILE"], [".toml"]),
    "fit": (
        ["fit", "FILE", "--method", "spectral"],
        [".csv", ".npy", ".npz", ".nc", ".tsv", ".parquet", ".mat", ".lvm", ".tdms", ".uff", ".txt"],
    ),
    "fit --scene": (["fit", "DATA", "--scene", "FILE"], [".toml"]),
    "fit --pixels": (["fit", "FILE", "--pixels", "all"], [".npy", ".nc", ".mp4"]),
    "detect": (["detect", "FILE"], [".npy", ".nc", ".mp4", ".csv"]),
    "extract": (["extract", "FILE"], [".npy", ".nc", ".mp4", ".tif"]),
    "extract --mask": (["extract", "CUBE", "--mask", "FILE"], [".npy", ".png"]),
    "report": (["report", "FILE"], [".nc", ".csv", ".toml"]),
}


def _valid_bytes(suffix: str, folder: Path) -> bytes:
    """A small valid file of the format, to be truncated."""
    import xarray as xr

    p = folder / f"valid{suffix}"
    cube = np.arange(2 * 3 * 4, dtype=np.float64).reshape(2, 3, 4)
    if suffix == ".npy":
        np.save(p, cube)
    elif suffix == ".npz":
        np.savez(p, time=np.arange(8) / 10, intensity=np.ones(8))
    elif suffix == ".nc":
        xr.Dataset({"intensity": (("time", "y", "x"), cube)}, coords={"time": [0.0, 0.1]}).to_netcdf(
            p, engine="h5netcdf"
        )
    elif suffix == ".toml":
        p.write_bytes(Path(ROOF).read_bytes())
    else:
        p.write_text("time,intensity\n" + "".join(f"{i / 10},{i % 3}\n" for i in range(8)))
    data = p.read_bytes()
    p.unlink()
    return data


@st.composite
def bad_files(draw):
    """(verb, the command line with FILE, suffix, kind, the file's bytes or a recipe)."""
    verb = draw(st.sampled_from(sorted(FILE_VERBS)))
    argv, suffixes = FILE_VERBS[verb]
    suffix = draw(st.sampled_from(suffixes))
    kind = draw(st.sampled_from(["empty", "truncated", "garbage", "text"]))
    if kind == "garbage":
        payload = b"\x00\xff\xfe" + draw(st.binary(max_size=200))
    elif kind == "text":
        payload = draw(st.sampled_from([b"hello", b"<script>alert(1)</script>\n", b"=1+1,@x\n-1,+2\n", b"[[[\n"]))
    else:
        payload = draw(st.floats(0.05, 0.6))  # the fraction of a valid file kept
    return verb, argv, suffix, kind, payload


def _check_bad_file(verb, argv, suffix, kind, payload) -> None:
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        if kind == "empty":
            data = b""
        elif kind == "truncated":
            valid = _valid_bytes(suffix, folder)
            data = valid[: max(1, int(len(valid) * payload))]
        else:
            data = payload
        bad = folder / f"in{suffix}"
        bad.write_bytes(data)
        (folder / "data.csv").write_text("time,intensity\n" + "".join(f"{i / 100},{287 + i % 3}\n" for i in range(64)))
        np.save(folder / "cube.npy", np.ones((4, 3, 3)))
        names = {"FILE": str(bad), "DATA": str(folder / "data.csv"), "CUBE": str(folder / "cube.npy")}
        _refused(folder, [names.get(a, a) for a in argv], None)


@settings(**CONTRACT, derandomize=True, max_examples=150)
@given(bad_files())
def test_every_verb_refuses_bad_files_in_one_line(case):
    _check_bad_file(*case)


@pytest.mark.slow
@settings(**CONTRACT, derandomize=False, max_examples=1500)
@given(bad_files())
def test_every_verb_refuses_bad_files_in_one_line_randomized(case):
    _check_bad_file(*case)


# ---------------------------------------------------------------- user text written into outputs

TEXTS = st.one_of(
    st.sampled_from(["V\n1,2", "a\r\nb", "x\u2028y", "=cmd|' /C calc'!A0", "<script>alert(1)</script>", "\x85"]),
    st.text(max_size=20),
)


@settings(**CONTRACT, derandomize=True, max_examples=15)
@given(units=TEXTS, name=st.sampled_from(["a\nb.nc", "=x.nc", "<b>.nc", "plain.nc", "a\rb\u2028.nc"]))
def test_extract_keeps_user_text_inside_the_csv_comments(units, name):
    """A units attribute or a file name holding a line break stays in its '#' comment line: every
    other line of series.csv is the header or a row of numbers."""
    import tempfile

    import xarray as xr

    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / name
        cube = np.arange(4 * 2 * 2, dtype=np.float64).reshape(4, 2, 2)
        ds = xr.Dataset({"intensity": (("time", "y", "x"), cube, {"units": units})}, coords={"time": np.arange(4) / 10})
        ds.to_netcdf(src, engine="h5netcdf")
        out = Path(tmp) / "out"
        code, _, err, _ = call("extract", str(src), "--series", "region", "-o", str(out))
        assert code == 0, err
        lines = (out / "series.csv").read_text(encoding="utf-8").split("\n")
        body = [ln for ln in lines if ln and not ln.startswith("#")]
        assert body[0] == "time,intensity", lines
        assert all(len(row.split(",")) == 2 and all(np.isfinite(float(v)) for v in row.split(",")) for row in body[1:])
        assert not any(c in "".join(lines) for c in "\r\u2028\x85")

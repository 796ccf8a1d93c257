"""A commented scene file for a real observation: a sunlit roof on a resonant building frame, seen
by one pixel of a camera (satellite, aircraft or tripod), whose tilt resonance and drive lines
`vibinverse fit` infers. `vibinverse init` writes it from answers (`SceneAnswers`).

    text = scene_template(SceneAnswers(fs=30.0, duration=60.0, resonance=2.5, drive=(7.0,)))
    write_scene_template("obs/scene.toml", SceneAnswers(date="2024-06-21", hour=13.5, latitude=48.1, longitude=11.6))

Every key of the text carries a comment: what it is, its unit, where to find the value. The text is
checked by loading it as `vibinverse fit` does (`forward.scene_file.load_scene`); a bad answer raises
`vibinverse.errors.InputError` with one line naming the answer's command-line flag and its range.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import math
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path

from forward.errors import SceneError as ForwardSceneError
from forward.materials import LIBRARY, Fresnel
from forward.scene_file import MAX_SAMPLES, load_scene
from forward.validation import interval, one_line
from vibinverse.errors import InputError
from vibinverse.io.atomic import write_all
from vibinverse.io.series import MIN_CYCLES

__all__ = ["SceneAnswers", "check_answer", "flag", "scene_template", "toml_string", "write_scene_template"]

DEFAULT_SUN = (60.0, 180.0)  # degrees: the paper's sec. 4.1/4.2 sun (pi/3, pi)
SPECULAR_OFFSET = 0.01  # rad: a default sensor this far above the sun's mirror direction (the paper's)
MAX_TITLE = 1000  # characters
MAX_DRIVE_LINES = 100
ROOF = "roof"  # the surface's name: fit's parameters are surfaces.roof.motion.*


@dataclass(frozen=True)
class SceneAnswers:
    """What an analyst knows about an observation. Angles in degrees (the file holds radians),
    lengths in m, frequencies in Hz. A None sun angle or view angle takes its default: the sun at
    (60, 180) degrees when no date is given; the sensor SPECULAR_OFFSET rad above the sun's mirror
    direction (the centre of the specular lobe, where a tilt changes the signal most)."""

    title: str = "Roof on a resonant frame (real observation)"
    # the sun by date, local clock time and place (all four of date, hour, latitude, longitude) ...
    date: str | None = None  # YYYY-MM-DD, local date
    hour: float | None = None  # local clock time, hours after midnight (13.5 = 13:30)
    latitude: float | None = None  # degrees, north positive
    longitude: float | None = None  # degrees, east positive
    utc_offset: float = 0.0  # hours: local clock time = UTC + utc_offset
    # ... or by angles
    sun_inclination: float | None = None  # degrees above the horizon
    sun_azimuth: float | None = None  # degrees counter-clockwise from east (+x)
    view_inclination: float | None = None  # degrees above the horizon, seen from the roof
    view_azimuth: float | None = None  # degrees counter-clockwise from east, from the roof to the sensor
    fs: float = 200.0  # Hz, frame rate
    duration: float = 20.0  # s, length of the record
    footprint: tuple[float, float] = (50.0, 50.0)  # m, east-west and north-south extent of the pixel's footprint
    roof: tuple[float, float] = (50.0, 50.0)  # m, east-west and north-south sides of the roof
    resolution: int = 16  # subpixels per footprint side
    material: str = "steel"  # the roof's (forward.materials.LIBRARY)
    background: str = "ground"  # what the footprint sees around the roof
    lobe_width: float = 0.01  # rad, RMS facet slope of the roof (Fresnel materials)
    resonance: float = 3.0  # Hz, expected tilt resonance of the building frame
    damping_ratio: float = 0.02  # expected damping ratio of the tilt mode
    drive: tuple[float, ...] = (10.0,)  # Hz, expected drive lines (machinery); () = none
    drive_amplitude: float = 1e-3  # m, expected drive amplitude at the roof's corner base
    noise_sigma: float | None = None  # sensor noise in data units; None = unknown (the fit estimates it)
    base_noise: float = 1e-4  # m, RMS white base motion of each corner (wind, traffic)


def flag(field: str) -> str:
    """The command-line flag of an answer: "view_inclination" -> "--view-inclination"."""
    return "--" + field.replace("_", "-")


def scene_template(answers: SceneAnswers) -> str:
    """The commented TOML scene for `answers`, checked by loading it (`forward.scene_file.load_scene`).

    InputError (one line naming the answer's flag and its allowed range) for a bad answer."""
    a = _checked(answers)
    sun_lines, sun_angles = _sun_section(a)
    text = _render(a, sun_lines, sun_angles)
    _check_loads(text)
    return text


def write_scene_template(path: str | Path, answers: SceneAnswers, *, overwrite: bool = False) -> Path:
    """Write `scene_template(answers)` to `path` atomically (all or nothing); InputError when the
    file exists and `overwrite` is False, or when its folder is missing."""
    p = Path(path)
    text = scene_template(answers)
    if p.is_dir():
        raise InputError(f"output: {p} is a directory; give a file path")
    if p.exists() and not overwrite:
        raise InputError(f"output: {p} exists; refusing to replace it (--force replaces it)")
    if not p.parent.is_dir():
        raise InputError(f"output: cannot write {p}: no such directory")
    write_all({p: lambda tmp: tmp.write_text(text, encoding="utf-8")})
    return p


# ---------------------------------------------------------------------------------------- checks
def _fail(field: str, value: float, lo: float, hi: float, lo_open: bool, hi_open: bool, note: str = "") -> None:
    raise InputError(
        f"{flag(field)}: {value:g} is outside the allowed range {interval(lo, hi, lo_open, hi_open)}{note}"
    )


def _real(
    field: str, value: object, lo: float = -math.inf, hi: float = math.inf, note: str = "", **open_ends: bool
) -> float:
    """`value` as a finite float in [lo, hi] (ends open when asked), else one-line InputError."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"{flag(field)}: must be a number, got {one_line(repr(value), 60)}")
    v = float(value)
    if not math.isfinite(v):
        raise InputError(f"{flag(field)}: must be a finite number, got {v}")
    lo_open = open_ends.get("lo_open", False) or lo == -math.inf
    hi_open = open_ends.get("hi_open", False) or hi == math.inf
    if (v <= lo if lo_open else v < lo) or (v >= hi if hi_open else v > hi):
        _fail(field, v, lo, hi, lo_open, hi_open, note)
    return v


def _pair(field: str, value: object) -> tuple[float, float]:
    """A size in m: one number (a square) or two (east-west, north-south), each > 0."""
    items = list(value) if isinstance(value, (tuple, list)) else [value]
    if len(items) not in (1, 2):
        raise InputError(f"{flag(field)}: give one size (a square) or two (east-west, north-south), got {len(items)}")
    sizes = [_real(field, v, 0.0, math.inf, lo_open=True) for v in items]
    return (sizes[0], sizes[-1])


def _text(field: str, value: object, limit: int) -> str:
    if not isinstance(value, str):
        raise InputError(f"{flag(field)}: must be text, got {one_line(repr(value), 60)}")
    if len(value) > limit:
        raise InputError(f"{flag(field)}: {len(value)} characters; allowed at most {limit}")
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        raise InputError(f"{flag(field)}: not valid Unicode text (an undecodable byte?)") from None
    return value


def _material(field: str, value: object) -> str:
    if not isinstance(value, str) or value not in LIBRARY:
        raise InputError(
            f"{flag(field)}: unknown material {one_line(repr(value), 60)}; allowed: {', '.join(sorted(LIBRARY))}"
        )
    return value


# (lo, hi, lo_open, hi_open) of each numeric answer; resonance and drive lie in (0, fs/2)
ANSWER_RANGES: dict[str, tuple[float, float, bool, bool]] = {
    "hour": (0.0, 24.0, False, False),
    "latitude": (-90.0, 90.0, False, False),
    "longitude": (-180.0, 180.0, False, False),
    "utc_offset": (-14.0, 14.0, False, False),
    "sun_inclination": (0.0, 90.0, True, False),
    "sun_azimuth": (-math.inf, math.inf, True, True),
    "view_inclination": (0.0, 90.0, True, False),
    "view_azimuth": (-math.inf, math.inf, True, True),
    "fs": (0.0, math.inf, True, True),
    "duration": (0.0, math.inf, True, True),
    "lobe_width": (0.0, 0.5, True, False),
    "damping_ratio": (0.0, 1.0, False, True),
    "drive_amplitude": (0.0, math.inf, False, True),
    "noise_sigma": (0.0, math.inf, False, True),
    "base_noise": (0.0, math.inf, False, True),
}


def check_answer(field: str, value: object, fs: float | None = None) -> object:
    """One answer validated on its own and normalized (a float, a tuple, text); None stays None.
    `fs` (default: SceneAnswers' fs) bounds the resonance and drive lines. InputError names the
    answer's flag and its allowed range. (`scene_template` also checks the answers together.)"""
    if value is None:
        return None
    if field in ANSWER_RANGES:
        lo, hi, lo_open, hi_open = ANSWER_RANGES[field]
        return _real(field, value, lo, hi, lo_open=lo_open, hi_open=hi_open)
    if field in ("resonance", "drive"):
        nyq = (SceneAnswers.fs if fs is None else fs) / 2
        check = lambda f: _real(field, f, 0.0, nyq, " Hz (below fs/2)", lo_open=True, hi_open=True)
        if field == "resonance":
            return check(value)
        lines = value if isinstance(value, (tuple, list)) else (value,)
        if len(lines) > MAX_DRIVE_LINES:
            raise InputError(f"{flag('drive')}: {len(lines)} lines; allowed at most {MAX_DRIVE_LINES}")
        return tuple(check(f) for f in lines)
    if field in ("footprint", "roof"):
        return _pair(field, value)
    if field in ("material", "background"):
        return _material(field, value)
    if field == "title":
        return _text("title", value, MAX_TITLE)
    if field == "date":
        return _date(value)
    if field == "resolution":
        if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 4096:
            raise InputError(f"{flag('resolution')}: {one_line(repr(value), 60)} is not an integer in [1, 4096]")
        return value
    raise InputError(f"answers: unknown answer {one_line(repr(field), 60)}")


def _checked(a: SceneAnswers) -> SceneAnswers:
    """The answers validated and normalized (floats, tuples, the sun's default angles)."""
    if not isinstance(a, SceneAnswers):
        raise InputError(f"answers: must be a SceneAnswers, got {type(a).__name__}")
    by_date = {k: getattr(a, k) for k in ("date", "hour", "latitude", "longitude")}
    if any(v is not None for v in by_date.values()):
        missing = [k for k, v in by_date.items() if v is None]
        if missing:
            raise InputError(
                f"{flag(missing[0])}: missing; the sun by date needs --date, --hour, --latitude and --longitude"
            )
        for k in ("sun_inclination", "sun_azimuth"):
            if getattr(a, k) is not None:
                raise InputError(
                    f"{flag(k)}: give the sun either by --date/--hour/--latitude/--longitude "
                    "or by --sun-inclination/--sun-azimuth, not both"
                )
        sun = {}
    else:
        sun = {
            "sun_inclination": DEFAULT_SUN[0] if a.sun_inclination is None else a.sun_inclination,
            "sun_azimuth": DEFAULT_SUN[1] if a.sun_azimuth is None else a.sun_azimuth,
        }
    fs = check_answer("fs", a.fs)
    duration = check_answer("duration", a.duration)
    n = round(duration * fs) if math.isfinite(duration * fs) else math.inf
    if not 2 <= n <= MAX_SAMPLES:
        raise InputError(
            f"{flag('duration')}: {duration:g} s at {fs:g} Hz is {n} samples; allowed range [2, {MAX_SAMPLES}] samples"
        )
    values = {f.name: getattr(a, f.name) for f in dataclasses.fields(a)} | sun
    return SceneAnswers(**{name: check_answer(name, v, fs) for name, v in values.items()})


def _date(value: object) -> str:
    if not isinstance(value, str) or not re.fullmatch(r"\d{4}-\d{2}-\d{2}", value):
        raise InputError(f"{flag('date')}: expected YYYY-MM-DD, got {one_line(repr(value), 60)}")
    try:
        return dt.date.fromisoformat(value).isoformat()
    except ValueError:
        raise InputError(f"{flag('date')}: {value} is not a calendar date (YYYY-MM-DD)") from None


# ------------------------------------------------------------------------------------ rendering
def toml_string(text: str) -> str:
    """`text` as a TOML basic string: quotes, backslashes and every control character escaped
    (json.dumps alone leaves DEL unescaped and writes astral characters as surrogate pairs, which
    TOML rejects); other characters stay as they are (the file is UTF-8)."""
    out = []
    for c in text:
        if c == '"':
            out.append('\\"')
        elif c == "\\":
            out.append("\\\\")
        elif c in "\n\t\r":
            out.append({"\n": "\\n", "\t": "\\t", "\r": "\\r"}[c])
        elif ord(c) < 0x20 or ord(c) == 0x7F or 0x80 <= ord(c) < 0xA0:
            out.append(f"\\u{ord(c):04x}")
        else:
            out.append(c)
    return '"' + "".join(out) + '"'


def _num(v: float) -> str:
    """A finite float as TOML (repr round-trips)."""
    return repr(float(v))


def _deg(v: float) -> str:
    """An angle in degrees as the file's expression in radians."""
    return f'"radians({_num(v)})"'


def _interval(size: float) -> str:
    return f"[{_num(-size / 2)}, {_num(size / 2)}]"


def _sun_section(a: SceneAnswers) -> tuple[list[str], tuple[float, float]]:
    """The [sun] table's lines and the sun's (elevation, scene azimuth) in rad."""
    if a.date is not None:
        from forward.solar import sun_angles

        try:
            angles = sun_angles(a.date, a.hour, a.latitude, a.longitude, a.utc_offset)
        except ForwardSceneError as exc:
            raise InputError(_flag_message(str(exc))) from None
        lines = [
            "# The sun by date, local clock time and place: the loader computes its position (pvlib's NREL SPA,",
            "# apparent elevation). Instead, give inclination and azimuth (rad) and remove these five keys.",
            f"date = {toml_string(a.date)}  # YYYY-MM-DD: local date of the observation",
            "# local clock time of the record's middle, from the camera's timestamps (13.5 = 13:30)",
            f"hour = {_num(a.hour)}  # h after midnight, in [0, 24]",
            f"latitude = {_num(a.latitude)}  # degrees north (south negative), in [-90, 90]: of the building",
            f"longitude = {_num(a.longitude)}  # degrees east (west negative), in [-180, 180]: of the building",
            "# local clock time = UTC + utc_offset: 0 when the timestamps are UTC (mind daylight saving time)",
            f"utc_offset = {_num(a.utc_offset)}  # h, in [-14, 14]",
            f"# At that time the sun stands {math.degrees(angles[0]):.3f} deg above the horizon, at scene azimuth "
            f"{math.degrees(angles[1]):.3f} deg.",
        ]
        return lines, angles
    lines = [
        "# The sun by angles. Instead, give date (YYYY-MM-DD), hour (local clock time), latitude, longitude",
        "# (degrees) and utc_offset (h), and remove these two keys: the loader then computes the sun's position.",
        "# The sun's ELEVATION above the horizon (90 deg - solar zenith angle), from an ephemeris or the",
        "# image's metadata (sun elevation / solar zenith angle):",
        f"inclination = {_deg(a.sun_inclination)}  # rad, in [1e-9, pi/2]",
        "# Counter-clockwise from east (+x) towards north (+y); a compass bearing B (clockwise from north, as",
        "# metadata give the solar azimuth) is radians(90 - B):",
        f"azimuth = {_deg(a.sun_azimuth)}  # rad",
    ]
    return lines, (math.radians(a.sun_inclination), math.radians(a.sun_azimuth))


def _view(a: SceneAnswers, sun: tuple[float, float]) -> tuple[float, float, list[str]]:
    """(view inclination, view azimuth) in degrees and a note on the ones not given."""
    inc, az = a.view_inclination, a.view_azimuth
    missing = [n for n, v in (("inclination", inc), ("azimuth", az)) if v is None]
    note = []
    if missing:
        note = [
            f"# NOT GIVEN ({' and '.join(missing)}): assumed near the specular direction (the sun mirrored in",
            f"# the flat roof, {SPECULAR_OFFSET} rad higher). Replace with the real viewing geometry.",
        ]
    if inc is None:
        up = sun[0] + SPECULAR_OFFSET
        inc = math.degrees(up if up <= math.pi / 2 else sun[0] - SPECULAR_OFFSET)
    if az is None:
        az = math.degrees(math.remainder(sun[1] + math.pi, 2 * math.pi))
    return inc, az, note


def _render(a: SceneAnswers, sun_lines: list[str], sun: tuple[float, float]) -> str:
    view_inc, view_az, view_note = _view(a, sun)
    nyq = a.fs / 2
    # the frame model's default frequency priors start at MIN_CYCLES in the record (first to last
    # sample), at least 0.2 Hz
    lo = max(0.2, MIN_CYCLES / (a.duration - 1.0 / a.fs) * (1.0 + 1e-9)) if a.duration * a.fs > 2 else 0.2
    g = lambda v: f"{v:.4g}"  # prior bounds, rounded for reading
    r = a.resonance
    lateral = r * 2 / math.sqrt(3)  # as in the paper's frame: lateral 4 Hz for a 2 sqrt(3) Hz tilt
    fx, fy = a.footprint
    rx, ry = a.roof
    fresnel = isinstance(LIBRARY[a.material], Fresnel)
    k1 = (2 * math.pi * r) ** 2 / 12  # per unit mass
    toml_list = lambda values: "[" + ", ".join(values) + "]"
    drive = toml_list(_num(f) for f in a.drive)
    amps = toml_list(_num(a.drive_amplitude) for _ in a.drive)
    phases = toml_list("0.0" for _ in a.drive)
    materials = ", ".join(f"{k} ({'Fresnel' if isinstance(v, Fresnel) else 'Lambertian'})" for k, v in LIBRARY.items())
    if a.noise_sigma is None:
        sigma = ["# Unknown, so 0 here: `fit` estimates it (default prior loguniform(1e-8, 1e3))."]
    else:
        sigma = [
            "# The sensor's noise sd in the data's units (e.g. the sd of a dark or flat patch); `fit` estimates it"
        ]
    m = f"surfaces.{ROOF}.motion"
    extra = [
        f'# "{m}.{name}[{i}]" = "{prior}"'
        for i, f in enumerate(a.drive)
        if i > 0
        for name, prior in (
            ("drive_frequency", f"uniform({g(max(lo, 0.95 * f))}, {g(min(nyq, 1.05 * f))})"),
            ("drive_amplitude", "uniform(0.0, 0.05)"),
            ("drive_phase", "uniform(-pi, pi)"),
        )
    ]
    out = [
        "# Scene for a real observation, written by `vibinverse init`: a sunlit roof on a resonant building",
        "# frame, seen by one pixel of a camera. Fit a measured series (CSV: time,intensity) with",
        "#     vibinverse fit DATA --scene scene.toml",
        "# and see the signal this scene predicts with `vibinverse simulate scene.toml --plot`.",
        "#",
        "# Conventions: SI units; angles in radians, written here as radians(DEGREES) expressions (any number or",
        '# expression such as "pi/3 + 0.01" works); frequencies in Hz. Scene axes: x east, y north, z up.',
        "# INCLINATION is the ELEVATION above the horizon (not the zenith angle): 90 deg is straight up.",
        "# AZIMUTH is counter-clockwise from +x (east): east 0, north 90, west 180, south -90 degrees.",
        "# Both point away from the roof: towards the sun, towards the sensor.",
        "#",
        "# By default `fit` estimates (the model's default priors; [infer] at the end changes them):",
        f"#   {m}.tilt_frequency, .tilt_damping_ratio    the building's tilt resonance",
        f"#   {m}.drive_frequency, .drive_amplitude, .drive_phase    the first drive line",
        f"#   {m}.noise_rms, noise.sigma    the base motion and the sensor noise",
        "# so their values below are guesses (used by `simulate` and `design`; further drive lines are held at",
        "# them unless [infer] frees them). Every other value is taken as known: measure it.",
        "#",
        "# The frame likelihood models the pixel's absolute level (radiance per unit irradiance, times",
        "# sun.irradiance): fit data calibrated to that scale, or set sun.irradiance to the data's gain.",
        f"title = {toml_string(a.title)}  # free text, shown in plots and reports",
        "",
        "[sun]",
        *sun_lines,
        "# Scales the whole signal: the data's gain (1 = data in radiance per unit solar irradiance).",
        "irradiance = 1.0  # W/m^2, > 0",
        "",
        "[sensor]",
        *view_note,
        "# The SENSOR's ELEVATION seen from the roof: 90 deg looks straight down (nadir). A satellite's view",
        "# zenith angle Z (off-nadir angle at the ground, from the image's metadata) is radians(90 - Z).",
        f"inclination = {_deg(view_inc)}  # rad, in [1e-9, pi/2]",
        "# Direction from the roof towards the sensor, counter-clockwise from east. A compass bearing B",
        "# (clockwise from north, as metadata give the view azimuth) is radians(90 - B).",
        f"azimuth = {_deg(view_az)}  # rad",
        '# polarizer = "none"  # "none", "s", "p" or an angle (rad): a polarizing filter in front of the lens',
        "",
        "[sampling]",
        "# `fit` takes the sampling from the data (its time column, or --fs); these serve `simulate` and `design`.",
        f"fs = {_num(a.fs)}  # Hz, > 0: frame rate of the camera",
        f"duration = {_num(a.duration)}  # s, > 0: length of the record (2 .. 1e8 samples)",
        "",
        "[noise]",
        *sigma,
        f"sigma = {_num(a.noise_sigma or 0.0)}  # data units, >= 0: additive Gaussian sensor noise",
        "",
        "[footprint]",
        "# The ground rectangle one pixel sees, here centred on the roof: the camera's ground sample distance",
        "# (or range x IFOV). Shift both ranges when the pixel is off the roof's centre.",
        f"x = {_interval(fx)}  # m, [min, max]: east-west ({fx:g} m)",
        f"y = {_interval(fy)}  # m, [min, max]: north-south ({fy:g} m)",
        f"resolution = {a.resolution}  # subpixels per side, 1..4096 (a rigid roof needs few)",
        "",
        "[background]",
        f"material = {toml_string(a.background)}  # what the footprint sees around the roof (static); as the roof's",
        *(
            [f"lobe_width = {_num(a.lobe_width)}  # rad, in (0, 0.5]: RMS facet slope (a Fresnel background)"]
            if isinstance(LIBRARY[a.background], Fresnel)
            else []
        ),
        "",
        f"[surfaces.{ROOF}]",
        "# The roof's rectangle at rest, from a map or the image (the footprint's axes).",
        f"x = {_interval(rx)}  # m, [min, max]: east-west ({rx:g} m)",
        f"y = {_interval(ry)}  # m, [min, max]: north-south ({ry:g} m)",
        f"# One of: {materials};",
        "# or a table: {index = [re, im]}, {albedo = 0.3}, {conductivity = 1.4e6, wavelength = 5.5e-7}.",
        f"material = {toml_string(a.material)}",
        *(
            [
                "# RMS facet slope of the roof's surface: the width of its glint (0.01 = a smooth sheet).",
                f"lobe_width = {_num(a.lobe_width)}  # rad, in (0, 0.5]",
            ]
            if fresnel
            else [f"# lobe_width = {_num(a.lobe_width)}  # rad: for Fresnel materials only (this one is Lambertian)"]
        ),
        "",
        f"[surfaces.{ROOF}.motion]",
        "# A rigid roof on four corner springs (paper sec. 4.2), written in modal form. For a uniform plate on",
        "# corner springs the tilt resonance is f_tilt = sqrt(12 k_vertical / mass) / (2 pi): the physical form",
        f"# k_vertical = mass (2 pi f_tilt)^2 / 12 = {k1:.6g} N/m per kg of mass for f_tilt = {r:g} Hz, and",
        "# f_vertical = f_tilt / sqrt(3). k_vertical, b_vertical, k_lateral, b_lateral (N/m, N s/m) may replace",
        "# the four *_frequency and *_damping_ratio keys.",
        'kind = "frame"',
        "mass = 1.0  # kg, > 0: only k/mass and b/mass matter to the motion",
        "# The EXPECTED tilt resonance of the building (a guess; `fit` estimates it), and its damping ratio.",
        f"tilt_frequency = {_num(r)}  # Hz, > 0",
        f"tilt_damping_ratio = {_num(a.damping_ratio)}  # in [0, 1)",
        "# Sideways sway: a rigid roof's normal does not change, so a pixel does not see it (not fitted).",
        f"lateral_frequency = {_num(lateral)}  # Hz, > 0",
        f"lateral_damping_ratio = {_num(a.damping_ratio)}  # in [0, 1)",
        "# EXPECTED lines of machinery shaking the building (motors, fans, pumps); [] = none. `fit` estimates",
        "# the first line's frequency, amplitude (radius of the circular base motion) and phase.",
        f"drive_frequency = {drive}  # Hz, each in (0, fs/2)",
        f"drive_amplitude = {amps}  # m, >= 0, one per line (a guess)",
        f"drive_phase = {phases}  # rad, one per line",
        "# Corner where the drive enters: 0..3 = (+,+), (-,+), (-,-), (+,-) half-sides (east, north).",
        "drive_corner = 0",
        "drive_plane = [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]  # two perpendicular directions of the drive's circle",
        "# White base motion (wind, traffic) at every corner and axis: it excites the resonance (fitted).",
        f"noise_rms = {_num(a.base_noise)}  # m, >= 0",
        'model = "linear"  # "linear" or "nonlinear" (`simulate` only; slower)',
        "",
        "# [infer.free] names the free parameters of `fit` and their priors; a parameter it does not list is",
        "# held at its value above. Uncommented as it stands, it gives the default priors (frequencies from 3",
        "# cycles in the record up to fs/2), except tilt_frequency: narrowed to [guess / 2, 2 guess] here.",
        "# [infer.free]",
        f'# "{m}.tilt_frequency" = "uniform({g(max(lo, r / 2))}, {g(min(nyq, 2 * r))})"',
        f'# "{m}.tilt_damping_ratio" = "loguniform(0.001, 0.5)"',
        *(
            [
                f'# "{m}.drive_frequency" = "uniform({g(lo)}, {g(nyq)})"',
                f'# "{m}.drive_amplitude" = "uniform(0.0, 0.05)"',
                f'# "{m}.drive_phase" = "uniform(-pi, pi)"',
            ]
            if a.drive
            else []
        ),
        f'# "{m}.noise_rms" = "loguniform(1e-7, 0.1)"',
        '# "noise.sigma" = "loguniform(1e-8, 1000.0)"',
        *(["# Further drive lines, each near its guess (+-5 %):", *extra] if extra else []),
    ]
    return "\n".join(out) + "\n"


# ------------------------------------------------------------------------------------ loading
_FLAG_OF_KEY = {
    "sun.date": "date",
    "sun.hour": "hour",
    "sun.latitude": "latitude",
    "sun.longitude": "longitude",
    "sun.utc_offset": "utc_offset",
    "sun.inclination": "sun_inclination",
    "sun.azimuth": "sun_azimuth",
    "sensor.inclination": "view_inclination",
    "sensor.azimuth": "view_azimuth",
    "sampling.fs": "fs",
    "sampling.duration": "duration",
    "sampling": "duration",
    "footprint.x": "footprint",
    "footprint.y": "footprint",
    "footprint.resolution": "resolution",
    "background.material": "background",
    f"surfaces.{ROOF}.x": "roof",
    f"surfaces.{ROOF}.y": "roof",
    f"surfaces.{ROOF}.material": "material",
    f"surfaces.{ROOF}.lobe_width": "lobe_width",
    f"surfaces.{ROOF}.motion.tilt_frequency": "resonance",
    f"surfaces.{ROOF}.motion.tilt_damping_ratio": "damping_ratio",
    f"surfaces.{ROOF}.motion.frequency": "drive",
    f"surfaces.{ROOF}.motion.drive_frequency": "drive",
    f"surfaces.{ROOF}.motion.drive_amplitude": "drive_amplitude",
    f"surfaces.{ROOF}.motion.noise_rms": "base_noise",
    "noise.sigma": "noise_sigma",
}


def _flag_message(message: str) -> str:
    """A scene error's message with its leading scene key replaced by the answer's flag."""
    key, sep, rest = message.partition(":")
    base = re.sub(r"\[\d+\]$", "", key.strip())
    if sep and base in _FLAG_OF_KEY:
        return f"{flag(_FLAG_OF_KEY[base])}:{rest}"
    return f"scene template: {message}"


def _check_loads(text: str) -> None:
    """Load `text` as `vibinverse fit` does; a SceneError becomes a one-line InputError."""
    with tempfile.TemporaryDirectory(prefix="vibinverse-init-") as tmp:
        path = Path(tmp) / "scene.toml"
        path.write_text(text, encoding="utf-8")
        try:
            load_scene(path)
        except ForwardSceneError as exc:
            raise InputError(_flag_message(str(exc))) from None

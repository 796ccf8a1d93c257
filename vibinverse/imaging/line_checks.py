"""What a detected line is, beyond "the power at this frequency is not noise": a structure's
vibration, or something of the recording (instrument lines, artefacts).

A line passes the detection map's false-alarm test (white-noise and empirical nulls alike) when
its power is real; real periodic power in a video need not be vibration. Each `LineCheck` looks
at one kind of evidence and names what the line is instead; the first that fires gives the line's
`kind`, and a line none fires on is "vibration" (claimed). A check is a class registered in
`LINE_CHECKS` (`register_line_check`): a new artefact is a new class. A `LineNote`
(`LINE_NOTES`, `register_line_note`) says what to know about a line whatever its kind: a slow
line's (`slow_lines`: 1-4 cycles per record) frequency is known to about a bin, and any slow
change of a region looks like it.

No equation of the paper is used here.
"""

from __future__ import annotations

import dataclasses
from abc import ABC, abstractmethod

import numpy as np

#: a line carried only by clusters this small is not a structure ("1-3 pixels scattered")
SCATTERED_PIXELS = 3
#: ... when there are at least this many of them (one small cluster may be a point target)
SCATTERED_CLUSTERS = 3
#: a slow line needs a cluster this big: a sway moves a structure's edge, tens of pixels long, where the
#: slow lines of the nine tuning-fork videos of ../shared/realdata-dev (whole, static part, shuffled) are
#: specks of at most 24 pixels (codec blocks stepping at keyframes; the struck fork's own slow change)
SLOW_STRUCTURE_PIXELS = 32
#: a line within this many Fourier bins of fs / m is a pattern of frames, m -> bins: half a bin (a
#: pattern's line sits on its frequency; a short clip's bins are wide, and a vibration half a bin away
#: stays one), 1.5 at fs / 2, which the grid's last bin (one short of Nyquist) shows a bin low
PATTERN_BINS = {2: 1.5, 3: 0.5, 4: 0.5}
#: a comb: at least COMB_LINES lines at multiples of fs / m, m in COMB_PERIODS, its teeth >= COMB_SPACING bins apart
COMB_LINES, COMB_PERIODS, COMB_SPACING = 3, range(5, 33), 3
VIBRATION = "vibration"


@dataclasses.dataclass(frozen=True)
class LineEvidence:
    """What the detection map knows about one line."""

    frequency: float  # Hz
    df: float  # Fourier resolution 1 / T, Hz
    nyquist: float  # Hz (half the median frame rate)
    uniform: bool  # uniform frame times
    cluster_sizes: tuple[int, ...]  # pixels of each cluster that carries the line
    frame_median: float  # median whitened power over the whole frame at the line's bin
    frame_wide: bool  # at least half the frame's pixels carry power there (`EmpiricalNull.frame_wide`)
    comb_period: int | None = None  # frames m of a comb of lines at multiples of fs / m it belongs to (`frame_combs`)
    cycles: float | None = None  # a slow line's cycles in the record (`slow_lines`); None: not slow
    slow_passing: tuple[int, ...] = ()  # the other slow bins (their cycles) that pass with it, in its line
    clipped_share: float = 0.0  # a slow line's share of pixels that reach the ends of the range in some frame
    motion_share: float = 0.0  # a slow line's share of power that the frame's motion explains (`slow_lines`)
    light_share: float = 0.0  # a slow line's share of power that a change of its pixels' light explains


class LineCheck(ABC):
    """One kind of evidence that a line is not a structure's vibration."""

    kind: str  # the line's kind when the check fires

    @abstractmethod
    def reason(self, line: LineEvidence) -> str | None:
        """Why the line is of this kind (one sentence), or None."""


LINE_CHECKS: dict[str, LineCheck] = {}


def register_line_check(check: type[LineCheck]) -> type[LineCheck]:
    """Class decorator: add a check to `LINE_CHECKS` under its `name` (default: its kind; applied in
    registration order)."""
    LINE_CHECKS[getattr(check, "name", check.kind)] = check()
    return check


@register_line_check
class FrameWide(LineCheck):
    """The whole picture changes at the line: illumination (lamp flicker at twice the mains
    frequency, or its alias), auto-exposure, keyframe flicker, camera motion. A structure's
    vibration moves the intensity only where the image has contrast, not over half the frame."""

    kind = "frame-wide"

    def reason(self, line: LineEvidence) -> str | None:
        if line.frame_wide:
            return (
                f"half the frame's pixels carry it (median SNR {line.frame_median:.3g}): illumination, exposure, "
                "flicker or camera motion, or a structure that fills the frame"
            )
        return None


#: a slow line whose pixels' power the frame's motion explains at this share or more is the camera's
CAMERA_MOTION_SHARE = 0.1


@register_line_check
class CameraMotion(LineCheck):
    """A slow line at a frequency where the whole picture moves (the camera shakes, turns or
    zooms): the motion model fitted over the frame (`slow_lines.frame_model`) explains a tenth of
    its pixels' power or more. Static edges moved by the camera respond nonlinearly (sharper than
    the mean frame's gradient), so what is left there looks like a local sway; a sway is claimed
    only where it moves well beyond the camera."""

    kind = "frame-wide"
    name = "camera-motion"

    def reason(self, line: LineEvidence) -> str | None:
        if line.cycles is not None and line.motion_share >= CAMERA_MOTION_SHARE:
            return (
                f"the whole picture moves at this frequency (the frame's motion explains {line.motion_share:.0%} of "
                "its pixels' power): camera motion, or a structure that fills the frame"
            )
        return None


@register_line_check
class FramePattern(LineCheck):
    """Power at half, a third or a quarter of the frame rate: frames that alternate or repeat in a
    short pattern (interlacing, paired sensor readouts, a codec's I/P/B frame pattern and its
    alternating quantization) look like a line at fs / m, m = 2, 3, 4."""

    kind = "frame-pattern"

    def reason(self, line: LineEvidence) -> str | None:
        if not line.uniform:
            return None
        fs = 2.0 * line.nyquist
        for m, bins in PATTERN_BINS.items():
            if abs(line.frequency - fs / m) <= bins * line.df:
                return f"at 1/{m} of the frame rate ({fs / m:.6g} Hz): a pattern of frames, not vibration"
        return None


@register_line_check
class FrameComb(LineCheck):
    """Lines at several multiples of fs / m (m >= 5 frames): a pattern of frames that repeats every
    m frames (a codec's mini-GOP, B-frame pyramid or rate control) makes a comb of harmonics."""

    kind = "frame-pattern"
    name = "frame-comb"

    def reason(self, line: LineEvidence) -> str | None:
        if line.comb_period is not None:
            fs = 2.0 * line.nyquist
            return (
                f"one of >= {COMB_LINES} lines at multiples of 1/{line.comb_period} of the frame rate "
                f"({fs / line.comb_period:.6g} Hz): a pattern of frames, not vibration"
            )
        return None


def frame_combs(frequencies: list[float], fs: float, df: float) -> list[int | None]:
    """For each line frequency (Hz), the period m (frames, COMB_PERIODS) of the first comb of lines it
    belongs to: at least COMB_LINES lines within PATTERN_BINS[3] bins of multiples of fs / m,
    multiples COMB_SPACING bins apart or more; None when it belongs to none."""
    out: list[int | None] = [None] * len(frequencies)
    f = np.asarray(frequencies, dtype=np.float64)
    tol = PATTERN_BINS[3] * df
    for m in COMB_PERIODS:
        base = fs / m
        if base < COMB_SPACING * df or f.size < COMB_LINES:
            continue
        j = np.round(f / base)
        on = (j >= 1) & (np.abs(f - j * base) <= tol)
        if on.sum() >= COMB_LINES:
            for i in np.flatnonzero(on):
                out[i] = out[i] if out[i] is not None else m
    return out


@register_line_check
class Unlocated(LineCheck):
    """Power in the frame's maximum only: no pixel carries the line at the false-discovery level,
    so it has no place in the picture to be a structure's."""

    kind = "unlocated"

    def reason(self, line: LineEvidence) -> str | None:
        if not line.cluster_sizes:
            return "no pixel carries it at the false-discovery level alpha: nowhere in the picture"
        return None


@register_line_check
class Scattered(LineCheck):
    """Clusters of one to three pixels scattered over the frame (codec blocks, hot or quantized
    pixels) are not a vibrating structure; nor is a slow line on clusters of fewer than
    SLOW_STRUCTURE_PIXELS, even one (a sway moves a structure's edges, many pixels long)."""

    kind = "scattered"

    def reason(self, line: LineEvidence) -> str | None:
        sizes = line.cluster_sizes
        if len(sizes) >= SCATTERED_CLUSTERS and max(sizes) <= SCATTERED_PIXELS:
            return f"carried only by {len(sizes)} clusters of 1-{SCATTERED_PIXELS} pixels scattered over the frame"
        if line.cycles is not None and sizes and max(sizes) < SLOW_STRUCTURE_PIXELS:
            return (
                f"a slow line on clusters of fewer than {SLOW_STRUCTURE_PIXELS} pixels (the largest {max(sizes)}): "
                "a codec block's level or a pixel drifting, or a corner moved by the camera, not a structure's edge"
            )
        return None


#: a slow line whose pixels' power a change of their light explains at this share or more is a light's
LOCAL_LIGHT_SHARE = 0.5


@register_line_check
class LocalLight(LineCheck):
    """A slow line whose pixels brighten and darken together (`slow_lines.SlowSearch.light_share`):
    a light or a shade on a region, where a moving edge changes its two sides in opposite ways."""

    kind = "local-light"

    def reason(self, line: LineEvidence) -> str | None:
        if line.cycles is not None and line.light_share >= LOCAL_LIGHT_SHARE:
            return (
                f"its pixels brighten and darken together ({line.light_share:.0%} of their power): a light or a "
                "shade on a region, not a moving edge"
            )
        return None


@register_line_check
class Clipped(LineCheck):
    """A slow line carried mostly by pixels that reach the ends of the range (saturated or black in
    some frames): a slow change of the light moves them nonlinearly, which the common mode of the
    slow search (`slow_lines`) cannot take out. Slow lines only: at the other frequencies the light
    is not taken out, and a clipped pixel's vibration is still one."""

    kind = "clipped"

    def reason(self, line: LineEvidence) -> str | None:
        if line.cycles is not None and line.clipped_share >= 0.5:
            return (
                f"{line.clipped_share:.0%} of its pixels reach the ends of the range in some frame (clipped): a slow "
                "change of the light moves them nonlinearly"
            )
        return None


#: a slow line needs this many cycles in the record to be told from a drift
MIN_SLOW_CYCLES = 2


@register_line_check
class OneCycle(LineCheck):
    """A slow line at one cycle in the record: with the mean and the line taken out, a sway's single
    cycle and a region's slow drift (a shade creeping, a person moving, a structure settling, a hand
    on the tripod) look the same, so nothing says it oscillates. Checked last: a check that names
    what the power is comes first."""

    kind = "drift"

    def reason(self, line: LineEvidence) -> str | None:
        if line.cycles is not None and line.cycles < MIN_SLOW_CYCLES:
            return (
                "one cycle in the record: a sway cannot be told from a slow drift of the region; a record of "
                f"{MIN_SLOW_CYCLES} cycles or more (>= {MIN_SLOW_CYCLES / line.frequency:.3g} s) could tell"
            )
        return None


def classify(line: LineEvidence) -> tuple[str, str]:
    """(kind, reason) of a line: the first registered check that fires, else ("vibration", "")."""
    for check in LINE_CHECKS.values():
        why = check.reason(line)
        if why is not None:
            return check.kind, why
    return VIBRATION, ""


class LineNote(ABC):
    """Something to know about a line whatever its kind."""

    name: str

    @abstractmethod
    def note(self, line: LineEvidence) -> str | None:
        """The note (one sentence), or None."""


LINE_NOTES: dict[str, LineNote] = {}


def register_line_note(note: type[LineNote]) -> type[LineNote]:
    """Class decorator: add a note to `LINE_NOTES` under its `name` (applied in registration order)."""
    LINE_NOTES[note.name] = note()
    return note


@register_line_note
class Slow(LineNote):
    """A slow line (1-4 cycles in the record, `slow_lines`): its frequency is known to about one
    Fourier bin, and the slow search sees slow power in a region that the rest of the frame does not
    share, which a sway makes and so does any slow change of a region."""

    name = "slow"

    def note(self, line: LineEvidence) -> str | None:
        if line.cycles is None:
            return None
        also = ", ".join(str(c) for c in line.slow_passing)
        others = f" (also passing: {also} cycles, its harmonics or leakage, or the light's modulation of it)"
        return (
            f"slow: {line.cycles:.0f} cycles in the record, its frequency known to about +-{line.df:.3g} Hz (1/T)"
            + (others if also else "")
            + "; any slow change of a region (a sway, a shadow, a person walking, a drifting pixel) looks alike; "
            "a fit of its cluster (fit --pixels) is not calibrated for so few cycles yet, and its verdict says so"
        )


def notes(line: LineEvidence) -> str:
    """The notes of every registered `LineNote` that has one for the line, "; "-joined ("" for none)."""
    return "; ".join(n for n in (note.note(line) for note in LINE_NOTES.values()) if n)

"""What a detected line is, beyond "the power at this frequency is not noise": a structure's
vibration, or something of the recording (instrument lines, artefacts).

A line passes the detection map's false-alarm test (white-noise and empirical nulls alike) when
its power is real; real periodic power in a video need not be vibration. Each `LineCheck` looks
at one kind of evidence and names what the line is instead; the first that fires gives the line's
`kind`, and a line none fires on is "vibration" (claimed). A check is a class registered in
`LINE_CHECKS` (`register_line_check`): a new artefact is a new class.

No equation of the paper is used here.
"""

from __future__ import annotations

import dataclasses
from abc import ABC, abstractmethod

#: a line carried only by clusters this small is not a structure ("1-3 pixels scattered")
SCATTERED_PIXELS = 3
#: ... when there are at least this many of them (one small cluster may be a point target)
SCATTERED_CLUSTERS = 3
#: a line within this many Fourier bins of fs / m, m in PATTERN_PERIODS, is a pattern of frames
PATTERN_BINS = 1.5
PATTERN_PERIODS = (2, 3, 4)
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


class LineCheck(ABC):
    """One kind of evidence that a line is not a structure's vibration."""

    kind: str  # the line's kind when the check fires

    @abstractmethod
    def reason(self, line: LineEvidence) -> str | None:
        """Why the line is of this kind (one sentence), or None."""


LINE_CHECKS: dict[str, LineCheck] = {}


def register_line_check(check: type[LineCheck]) -> type[LineCheck]:
    """Class decorator: add a check to `LINE_CHECKS` (applied in registration order)."""
    LINE_CHECKS[check.kind] = check()
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
        for m in PATTERN_PERIODS:
            if abs(line.frequency - fs / m) <= PATTERN_BINS * line.df:
                return f"at 1/{m} of the frame rate ({fs / m:.6g} Hz): a pattern of frames, not vibration"
        return None


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
    pixels) are not a vibrating structure."""

    kind = "scattered"

    def reason(self, line: LineEvidence) -> str | None:
        sizes = line.cluster_sizes
        if len(sizes) >= SCATTERED_CLUSTERS and max(sizes) <= SCATTERED_PIXELS:
            return f"carried only by {len(sizes)} clusters of 1-{SCATTERED_PIXELS} pixels scattered over the frame"
        return None


def classify(line: LineEvidence) -> tuple[str, str]:
    """(kind, reason) of a line: the first registered check that fires, else ("vibration", "")."""
    for check in LINE_CHECKS.values():
        why = check.reason(line)
        if why is not None:
            return check.kind, why
    return VIBRATION, ""

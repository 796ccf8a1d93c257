"""What a detected line is: each check fires on its evidence only; the first that fires names it."""

import dataclasses

from vibinverse.imaging.line_checks import LINE_CHECKS, VIBRATION, LineEvidence, classify

PLAIN = LineEvidence(
    frequency=32.0, df=0.28, nyquist=125.0, uniform=True, cluster_sizes=(3000, 12), frame_median=0.7, frame_wide=False
)


def test_a_structure_line_is_vibration():
    assert classify(PLAIN) == (VIBRATION, "")


def test_each_kind_fires_on_its_evidence():
    cases = {
        "frame-wide": {"frame_wide": True, "frame_median": 3.0},
        "frame-pattern": {"frequency": 124.72},
        "unlocated": {"cluster_sizes": ()},
        "scattered": {"cluster_sizes": (1, 2, 3, 1)},
    }
    assert set(cases) <= set(LINE_CHECKS)
    for kind, change in cases.items():
        got, why = classify(dataclasses.replace(PLAIN, **change))
        assert got == kind and why, (kind, got)


def test_frame_patterns_at_a_third_and_a_quarter_of_the_frame_rate():
    for f in (250 / 3, 62.5):
        assert classify(dataclasses.replace(PLAIN, frequency=f))[0] == "frame-pattern"
    # four bins from a quarter: a fork at 64 Hz filmed at 250 fps stays vibration
    assert classify(dataclasses.replace(PLAIN, frequency=64.0))[0] == VIBRATION
    # irregular frame times have no frame pattern
    assert classify(dataclasses.replace(PLAIN, frequency=62.5, uniform=False))[0] == VIBRATION


def test_one_small_cluster_may_be_a_point_target():
    assert classify(dataclasses.replace(PLAIN, cluster_sizes=(2,)))[0] == VIBRATION
    assert classify(dataclasses.replace(PLAIN, cluster_sizes=(2, 1, 40)))[0] == VIBRATION

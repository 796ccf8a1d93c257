"""Paper Fig. 13 (quick): lines at the tilt resonance and the drive."""

import numpy as np
import pytest


def test_fig13_lines_at_tilt_resonance_and_drive(results):
    _, _, d = results
    assert d["fig13"]["drive_line_hz"] == pytest.approx(10.0, abs=0.3)
    assert d["fig13"]["tilt_line_hz"] == pytest.approx(2 * np.sqrt(3), abs=0.4)

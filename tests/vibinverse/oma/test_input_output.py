"""Input-output identification (vibinverse.oma.input_output): responses fitted given the measured force."""

import numpy as np
import pytest

from forward.motion.forced_modes import forced_modes
from vibinverse.errors import DataError, InputError
from vibinverse.io.channels import Channels
from vibinverse.oma import identify, mac
from vibinverse.oma.input_output import receptance

MODES = ((12.0, 0.02), (31.0, 0.015))
RESIDUES = np.array([[1.0, 0.6, -0.3], [0.4, -0.9, 0.7]])  # (modes, channels): shape x participation


def forced_record(seed: int, fs: float = 200.0, duration: float = 120.0, noise: float = 0.05) -> Channels:
    """Displacements of two modes driven by a measured band-limited white force, plus white sensor
    noise (`forward.motion.forced_modes`: sampled as a data-acquisition system samples)."""
    t, force, y = forced_modes(MODES, RESIDUES, fs=fs, duration=duration, noise=noise, seed=seed)
    values = np.column_stack([force, y])
    return Channels(t, values, ("force", "a", "b", "c"), ("N", "m", "m", "m"), "forced", inputs=("force",))


def test_receptance_is_the_oscillators_transfer():
    f = np.array([5.0, 10.0, 20.0])
    w = 2 * np.pi * 10.0
    big = 2 * np.pi * f
    assert np.allclose(receptance(10.0, 0.05, f, 0), 1 / (w * w - big * big + 2j * 0.05 * w * big))
    assert np.allclose(receptance(10.0, 0.05, f, 2), -(big**2) / (w * w - big * big + 2j * 0.05 * w * big))


@pytest.mark.parametrize("seed", [0, 1])
def test_modes_and_residue_shapes_from_a_measured_force(seed):
    """A regression test (one data set), not calibration: that is `examples/io_calibration.py`."""
    r = identify(forced_record(seed), quantity="displacement", band=(5.0, 60.0))
    assert [round(m.frequency) for m in r.modes] == [12, 31]
    assert r.names == ("a", "b", "c")
    for (f, zeta), a, m in zip(MODES, RESIDUES, r.modes, strict=True):
        assert abs(m.frequency - f) < 4 * m.frequency_sd + 1e-3 * f
        assert abs(m.damping_ratio - zeta) < 4 * m.damping_ratio_sd + 0.1 * zeta
        assert mac(m.shape, a) > 0.99
    assert any("input-output" in n for n in r.notes)


def test_two_inputs_are_refused_in_one_line():
    ch = forced_record(2, duration=10.0)
    two = Channels(ch.time, ch.values, ch.names, ch.units, "two", inputs=("force", "a"))
    with pytest.raises(InputError) as e:
        identify(two)
    assert "one measured input" in str(e.value) and "\n" not in str(e.value)


def test_a_gap_in_the_input_is_cut_out_not_filled():
    """A gap in the measured force: the fit runs on its longest stretch without one (noted), and
    finds the modes as the whole record does; a force with gaps everywhere is refused in one line."""
    ch = forced_record(4, duration=60.0)
    v = ch.values.copy()
    v[600:640, 0] = np.nan  # 0.2 s of the force lost at 3 s
    r = identify(Channels(ch.time, v, ch.names, ch.units, "gap", inputs=("force",)), quantity="displacement")
    assert [round(m.frequency) for m in r.modes] == [12, 31]
    assert any("longest stretch without them" in n and "95% of the record" in n for n in r.notes)
    v[::100, 0] = np.nan
    with pytest.raises(DataError) as e:
        identify(Channels(ch.time, v, ch.names, ch.units, "holes", inputs=("force",)), quantity="displacement")
    assert "longest stretch" in str(e.value) and "\n" not in str(e.value)


def test_a_constant_channel_is_refused_in_one_line():
    ch = forced_record(5, duration=10.0)
    for c, name in ((0, "force"), (2, "b")):
        v = ch.values.copy()
        v[:, c] = 3.0
        with pytest.raises(DataError) as e:
            identify(Channels(ch.time, v, ch.names, ch.units, "flat", inputs=("force",)))
        assert f"channel {name} is constant" in str(e.value) and "\n" not in str(e.value)

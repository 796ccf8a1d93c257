import numpy as np
import pytest
from scipy.signal import lfilter

from vibinverse.errors import DataError, InputError
from vibinverse.io.channels import Channels
from vibinverse.oma import identify, mac
from vibinverse.oma.band_model import quantity_of
from vibinverse.oma.result import signed_unit

from .conftest import modal_record

MODES = ((1.0, 0.02), (2.7, 0.015), (4.1, 0.01))
SHAPES = np.array([[0.2, -0.2, 0.95, 0.15], [-0.3, 0.2, 0.75, 0.55], [0.45, 0.8, 0.4, -0.03]])


@pytest.fixture(scope="module")
def three_modes():
    ch = modal_record(MODES, SHAPES, duration=600.0, seed=0)
    return identify(ch, quantity="displacement")


def test_three_modes_found_with_their_shapes(three_modes):
    r = three_modes
    assert len(r.modes) == 3
    for (f, zeta), v, m in zip(MODES, SHAPES, r.modes, strict=True):
        assert abs(m.frequency - f) / f < 0.01
        assert abs(np.log(m.damping_ratio / zeta)) < np.log(1.5)
        assert mac(m.shape, v) > 0.99
        assert np.linalg.norm(m.shape) == pytest.approx(1.0)
        assert m.shape[np.argmax(np.abs(m.shape))] > 0  # the sign convention
        lo, hi = m.frequency_interval
        assert lo < m.frequency < hi and m.frequency_sd > 0
        assert np.all(m.shape_interval[:, 0] <= m.shape_interval[:, 1])
    off = r.mac[~np.eye(3, dtype=bool)]
    assert off.max() < 0.9
    js = r.to_json()
    assert js["channels"] == ["c0", "c1", "c2", "c3"] and len(js["modes"]) == 3
    assert "mode 1: f = " in r.table()


def test_truth_within_three_sd_seed_0(three_modes):
    """A regression test (one data set), not calibration: that is `examples/oma_calibration.py`."""
    for (f, zeta), v, m in zip(MODES, SHAPES, three_modes.modes, strict=True):
        assert abs(m.frequency - f) < 3 * m.frequency_sd
        assert abs(m.damping_ratio - zeta) < 3 * m.damping_ratio_sd
        assert np.all(np.abs(m.shape - signed_unit(v)) < 3 * m.shape_sd + 1e-3)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_white_noise_has_no_modes(seed):
    rng = np.random.default_rng(seed)
    n = 20000
    ch = Channels(np.arange(n) / 50.0, rng.normal(size=(n, 4)), tuple("abcd"), ("m",) * 4, "null")
    assert identify(ch).modes == []


def test_coloured_independent_noise_has_no_modes():
    rng = np.random.default_rng(7)
    n = 20000
    y = lfilter([1.0], [1.0, -0.95], rng.normal(size=(n, 3)), axis=0)
    assert identify(Channels(np.arange(n) / 50.0, y, tuple("abc"), ("m",) * 3, "null")).modes == []


def test_few_gaps_are_filled_and_reported():
    ch = modal_record(MODES[:1], SHAPES[:1, :3], duration=300.0, seed=2)
    v = ch.values.copy()
    v[1000:1150, 1] = np.nan  # 0.3 % of the values
    r = identify(Channels(ch.time, v, ch.names, ch.units, "gappy"), quantity="displacement")
    assert len(r.modes) == 1 and abs(r.modes[0].frequency - 1.0) < 0.01
    assert any("missing values" in n for n in r.notes)


def _one_line(exc):
    assert "\n" not in str(exc.value)
    return str(exc.value)


def test_bad_input_is_refused_in_one_line():
    ch = modal_record(MODES[:1], SHAPES[:1, :3], duration=60.0, seed=3)
    t = ch.time.copy()
    t[5] += 0.3 * (t[6] - t[5])
    with pytest.raises(DataError) as e:
        identify(Channels(t, ch.values, ch.names, ch.units, "jitter"))
    assert "uniform" in _one_line(e)
    v = ch.values.copy()
    v[::5, 0] = np.nan
    with pytest.raises(DataError) as e:
        identify(Channels(ch.time, v, ch.names, ch.units, "holes"))
    assert "missing" in _one_line(e)
    with pytest.raises(DataError) as e:
        identify(Channels(ch.time, ch.values, ch.names, ch.units, "inputs", inputs=ch.names))
    assert "input" in _one_line(e)
    with pytest.raises(InputError) as e:
        identify(ch, quantity="strain rate")
    assert "quantity" in _one_line(e)
    with pytest.raises(InputError) as e:
        identify(ch, band=(5.0, 40.0))
    assert "band" in _one_line(e) and "Nyquist" in str(e.value)
    with pytest.raises(InputError) as e:
        identify(ch, modes=0)
    assert "modes" in _one_line(e)


def test_quantity_read_from_units():
    assert quantity_of(("m", "m")) == "displacement"
    assert quantity_of(("mm/s", "mm/s")) == "velocity"
    assert quantity_of(("g", "g", "g")) == "acceleration"
    assert quantity_of((None, None)) == "acceleration"
    assert quantity_of(("m", "m/s")) == "acceleration"  # mixed: the common OMA sensor


def test_the_report_escapes_channel_names(three_modes):
    import dataclasses

    from vibinverse.oma.report import oma_html

    named = dataclasses.replace(three_modes, names=("<script>x</script>", "b", "c", "d"))
    page = oma_html(named, "a<b>.csv")
    assert "<script>x" not in page and "&lt;script&gt;x&lt;/script&gt;" in page
    assert "<title>vibinverse modal identification: a&lt;b&gt;.csv</title>" in page


def test_a_band_up_to_nyquist_is_allowed_as_the_stamps_round_it():
    ch = modal_record(MODES[:1], SHAPES[:1, :3], fs=20.0, duration=120.0, seed=5)
    r = identify(ch, quantity="displacement", band=(0.2, 10.0))  # fs from the stamps: 9.99999999... Hz
    assert r.search[1] <= 0.5 * r.fs and len(r.modes) == 1

"""The nuisance-term search of a scene fit: the moves respect what the user fixes, the search finds
AR(1) sensor noise (and drops the then unidentified white noise), adds nothing to clean data, and
is skipped when every key is fixed."""

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

import vibinverse as vi
from tests.conftest import K, frame, frame_series
from vibinverse.models.frame import FrameModel
from vibinverse.models.modal import ModalModel
from vibinverse.selection.moves import MOVES
from vibinverse.selection.nuisance_search import NuisanceSearch, Reading, search_nuisance, wanted
from vibinverse.terms.nuisance import NuisanceSpec

SPECS = (
    st.tuples(
        st.sampled_from(["white", "ar1", "1/f"]),
        st.sampled_from(["none", "walk", "integrated"]),
        st.sampled_from([0, 6]),
        st.booleans(),
    )
    .filter(lambda s: s[3] or s[0] != "white")
    .map(lambda s: NuisanceSpec(*s))
)


@given(SPECS, st.sets(st.sampled_from(["noise", "drift", "gain", "white"])))
def test_moves_never_change_a_fixed_key(spec, fixed):
    for move in MOVES:
        for _, proposal in move.proposals(spec, frozenset(fixed)):
            assert proposal != spec
            for key in fixed:
                assert getattr(proposal, key) == getattr(spec, key), (move.name, key)
            assert proposal.white or proposal.noise != "white"


def test_the_search_runs_only_where_a_key_is_open():
    table = frame()
    assert wanted(table, FrameModel)
    assert not wanted({**table, "nuisance": {"noise": "white", "drift": "none", "gain": 0, "white": True}}, FrameModel)
    assert not wanted({"modal": {}}, ModalModel)


def _data(seed, ar=None):
    return frame_series(frame("noise.sigma=0" if ar else "noise.sigma=0.6"), seed, ar)


@pytest.mark.slow
def test_the_search_finds_ar1_noise_and_adds_nothing_to_clean_data():
    analyst = frame("noise.sigma=0.6")
    found = search_nuisance(analyst, _data(0, ar=(0.9, 0.6)))
    assert found.chosen.spec == NuisanceSpec(noise="ar1", white=False)
    assert found.criterion[0]["kept"] and sum(r["kept"] for r in found.criterion) == 3
    clean = search_nuisance(analyst, _data(1))
    assert clean.chosen.spec == NuisanceSpec()
    assert all(r["delta_bic"] > 0 for r in clean.criterion[1:])


@pytest.mark.slow
def test_a_default_scene_fit_reports_its_search_and_keeps_a_fixed_key():
    analyst = frame("noise.sigma=0.6")
    data = _data(0, ar=(0.9, 0.6))
    result = vi.fit(data, analyst, method="map", white=True)
    rows = result.diagnostics["nuisance_search"]
    assert all(r["white"] for r in rows)  # fixed by the caller: never removed
    assert result.summary()["data"]["model"]["terms"] == "AR(1) noise, white noise"
    tilt = result.summary()["parameters"][K + "tilt_frequency"]
    assert abs(tilt["map"] / (2 * math.sqrt(3)) - 1) < 0.01


def test_the_chosen_gain_drifts_start_keeps_its_constant():
    """The search's table (the fit's start) holds a scene gain drift's constant `gain.a0` beside its
    slow coefficients, and no white-noise sigma."""
    spec = NuisanceSpec(gain=2)
    values = {"gain.a0": -0.017, "gain.a1": 0.05, "gain.a2": -0.02, "noise.sigma": 0.6, K + "tilt_frequency": 3.4}
    table = NuisanceSearch(Reading(spec, values, -1.0, 5, 100)).table()
    assert table["start"] == {"gain.a0": -0.017, "gain.a1": 0.05, "gain.a2": -0.02}
    assert table["gain"] == 2

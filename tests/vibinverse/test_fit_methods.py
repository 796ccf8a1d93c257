"""The fitting methods are classes found by name (`vibinverse.pipeline.FIT_METHODS`), and so are the
kinds the bench, the multi-output model and the frame model used to compare as strings."""

import pytest

from vibinverse.errors import InputError
from vibinverse.pipeline import (
    FIT_METHODS,
    METHODS,
    CasadiMethod,
    FitMethod,
    SindyMethod,
    check_method,
    fit_method,
    run,
)
from vibinverse.verdict import approximation


def test_every_method_name_resolves_to_its_class_in_the_documented_order():
    assert METHODS == ("spectral", "sindy", "casadi", "map", "importance", "mcmc", "auto")
    assert tuple(FIT_METHODS) == METHODS
    for name in METHODS:
        cls = fit_method(name)
        assert issubclass(cls, FitMethod) and cls.name == name
        cls()  # concrete: every stage method is implemented
    assert [n for n in METHODS if fit_method(n).derivative_free] == ["map"]
    assert [n for n in METHODS if fit_method(n).sindy_seeds] == ["auto"]
    assert {n: fit_method(n).label for n in METHODS}["mcmc"] == "emcee"
    assert [n for n in METHODS if fit_method(n).samples_by_emcee] == ["mcmc"]
    assert fit_method("sindy") is SindyMethod and fit_method("casadi") is CasadiMethod


@pytest.mark.parametrize("bad", ["bogus", "MAP", "", None])
def test_an_unknown_method_is_one_line_naming_the_allowed_ones(bad):
    message = f"--method: {bad!r} is not one of spectral, sindy, casadi, map, importance, mcmc, auto"
    for call in (check_method, fit_method, lambda m: run(None, m)):  # refused before the posterior is read
        with pytest.raises(InputError) as err:
            call(bad)
        assert str(err.value) == message and "\n" not in str(err.value)


def test_an_older_summary_s_intervals_follow_its_method():
    """A summary written before `approximation`: the method's class says what its intervals are."""
    expected = {"spectral": "spectral", "sindy": "jackknife", "mcmc": None, "auto": None}
    for name in METHODS:
        assert approximation({"method": name}) == expected.get(name, "laplace"), name
    assert approximation({"method": "oma"}) == "laplace" and approximation({}) == "laplace"
    assert approximation({"method": "mcmc", "approximation": "laplace"}) == "laplace"


def test_multi_output_sources_know_their_names_order_and_test():
    from vibinverse.models.multi_output import SOURCE_KINDS, SOURCES, LineSource, ModeSource

    assert SOURCE_KINDS == ("mode", "line")
    assert SOURCES["mode"] is ModeSource and SOURCES["line"] is LineSource and len(SOURCES) == 2
    assert ModeSource.names(1) == ["modes[1].frequency", "modes[1].damping_ratio", "modes[1].rms"]
    assert LineSource.names(0) == ["lines[0].frequency", "lines[0].amplitude", "lines[0].phase"]
    assert ModeSource.order() == {"modes": 1, "lines": 0} and LineSource.order() == {"modes": 0, "lines": 1}
    test = LineSource.line_test(2, ["lines[2].frequency"])
    assert (test.label, test.null, test.frequency, test.deterministic) == (
        "line_2",
        {"lines[2].amplitude": 0.0},
        "lines[2].frequency",
        True,
    )
    test = ModeSource.line_test(0, [])
    assert (test.label, test.null, test.frequency, test.deterministic) == ("mode_0", {"modes[0].rms": 0.0}, None, False)


def test_the_robustness_noises_are_found_by_the_case_s_name():
    from vibinverse.bench.robustness_cases import CASES, NOISES
    from vibinverse.bench.robustness_oracle import ORACLE_NOISES

    assert set(NOISES) == set(ORACLE_NOISES) == {"white", "ar1", "1/f"}
    assert {c.noise for c in CASES.values()} <= set(NOISES)
    assert {k: o.modal_noise for k, o in ORACLE_NOISES.items()} == {"white": "white", "ar1": "ar1", "1/f": "white"}


def test_a_frame_surface_is_found_through_forward_s_motion_registry():
    from forward.motion import FrameMotion, PlateMotion
    from vibinverse.models.frame import FrameModel, frame_surface, motion_class

    assert motion_class({"motion": {"kind": "frame"}}) is FrameMotion
    assert motion_class({"motion": {"kind": "plate"}}) is PlateMotion
    assert motion_class({}) is None and motion_class({"motion": {"kind": "nope"}}) is None
    assert motion_class({"motion": {"kind": ["frame"]}}) is None
    table = {"surfaces": {"a": {"motion": {"kind": "plate"}}, "b": {"motion": {"kind": "frame"}}, "c": {}}}
    assert frame_surface(table) == "b" and FrameModel.describes(table)
    assert not FrameModel.describes({"surfaces": {"a": {"motion": {"kind": "plate"}}}})

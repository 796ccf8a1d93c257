"""The scene compiler: fast paths against the dense reference, casadi symbols, hard cases."""

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from forward.reduce import compile_scene
from forward.render import pixel_signal
from forward.scene_file import scene_from_table

SMALL = ("footprint.resolution=40", "sampling.duration=0.1")


def rel_error(fast, ref):
    return np.abs(fast - ref).max() / np.ptp(ref)


@pytest.mark.parametrize(
    "name, expected_kind",
    [
        ("roof_elastic", "chebyshev"),
        ("glass_brewster", "chebyshev"),
        ("roof_frame", "taylor2"),
        ("ground_rayleigh", "taylor2"),
    ],
)
def test_example_scenes_meet_rtol(scene, name, expected_kind):
    s = scene(name, *SMALL) if name != "roof_frame" else scene(name, "sampling.duration=2")
    ref = pixel_signal(s, seed=4)
    c = compile_scene(s, rtol=1e-5, seed=4)
    assert c.moving()[0].kind == expected_kind
    assert rel_error(c.signal(), ref) <= 1e-5
    assert c.error_bound() <= 1e-5 * np.ptp(ref) * 1.01  # the estimate meets the request it was built for


def test_rigid_roof_is_evaluated_at_one_point(scene):
    c = compile_scene(scene("roof_frame", "sampling.duration=1"), seed=0)
    assert c.moving()[0].detail.startswith("rigid: one facet stands for all 256 subpixels")


def test_large_amplitude_is_noticed(scene):
    s = scene("roof_elastic", *SMALL, "surfaces.roof.motion.center_deflection=0.05")  # Fig. 10 saturation
    ref = pixel_signal(s)
    c = compile_scene(s, rtol=1e-4)
    assert c.moving()[0].kind == "chebyshev"
    assert rel_error(c.signal(), ref) <= 1e-4
    taylor = compile_scene(s, rtol=1e-4, force="taylor2")
    assert taylor.moving()[0].error > 1e-4 * taylor.moving()[0].ptp  # its own bound says it is not enough
    assert rel_error(taylor.signal(), ref) > 1e-3  # and it is not


def test_centered_footprint_keeps_the_second_order_term(scene):
    s = scene("roof_elastic", *SMALL, "footprint.x=[-25, 25]", "footprint.y=[-25, 25]")
    ref = pixel_signal(s)
    for force in ("taylor2", "chebyshev"):
        x = compile_scene(s, force=force).signal()
        spec = np.abs(np.fft.rfft(x - x.mean()))
        assert np.fft.rfftfreq(x.size, 1e-3)[spec.argmax()] == pytest.approx(80.0)
        assert rel_error(x, ref) < 1e-3


def test_taylor_ac_part_survives_amplitudes_below_float64_resolution(scene):
    centered = ("footprint.x=[-25, 25]", "footprint.y=[-25, 25]")
    big = compile_scene(scene("roof_elastic", *SMALL, *centered, "surfaces.roof.motion.center_deflection=1e-6"))
    tiny = compile_scene(scene("roof_elastic", *SMALL, *centered, "surfaces.roof.motion.center_deflection=1e-9"))
    assert tiny.moving()[0].kind == "taylor2"
    ac_big, ac_tiny = (c.moving()[0].ac(*c.moving()[0].coords.T) for c in (big, tiny))
    assert np.all(np.isfinite(ac_tiny)) and np.ptp(ac_tiny) > 0
    # a centered footprint is second order: AC scales as amplitude squared, here by 1e-6. What is
    # left is a first-order term from roundoff-level asymmetry of the shape moments (~1e-7 of the
    # quadratic term at these amplitudes); the quartic term is (1e-7 / 0.01)^2 smaller still.
    np.testing.assert_allclose(ac_tiny, 1e-6 * ac_big, rtol=1e-5, atol=1e-5 * np.abs(ac_tiny).max())


@pytest.mark.parametrize(
    "name, overrides",
    [("roof_elastic", ()), ("ground_rayleigh", ()), ("roof_elastic", ("surfaces.roof.motion.center_deflection=0.05",))],
)
def test_reduced_observation_works_with_casadi_symbols(scene, name, overrides):
    c = compile_scene(scene(name, *SMALL, *overrides))
    surf = c.moving()[0]
    q = ca.SX.sym("q", surf.n_coords)
    f = ca.Function("x", [q], [c.observation([[q[i] for i in range(surf.n_coords)]])])
    j = ca.Function("dx", [q], [ca.jacobian(f(q), q)])
    for row in surf.coords[::17]:
        assert float(f(row)) == pytest.approx(float(c.observation([tuple(row)])), rel=1e-13)
    # exact derivatives agree with a central difference of the numpy evaluation
    row, h = surf.coords[5], 1e-6 * max(1.0, np.abs(surf.coords).max())
    fd = (
        c.observation([tuple(row + h * np.eye(surf.n_coords)[0])])
        - c.observation([tuple(row - h * np.eye(surf.n_coords)[0])])
    ) / (2 * h)
    assert float(j(row)[0]) == pytest.approx(fd, rel=1e-5)


def test_dense_path_refuses_symbols(scene):
    c = compile_scene(scene("roof_elastic", *SMALL), force="dense")
    assert c.moving()[0].kind == "dense"
    with pytest.raises(TypeError, match="dense"):
        c.moving()[0].evaluate(ca.SX.sym("q"))


def test_explain_names_each_surface_and_its_error(scene):
    text = compile_scene(scene("roof_elastic", *SMALL)).explain()
    assert "roof" in text and "chebyshev" in text and "background" in text and "est. error" in text


def random_scene(sun_inc, view_off, az_off, material, lobe, amp, freq, fx, fy, size):
    mat = {"steel": "steel", "glass": "glass", "aluminium": "aluminium", "ground": {"albedo": 0.4}}[material]
    surface = {
        "x": [-size, size],
        "y": [-size, size],
        "material": mat,
        "motion": {"kind": "plate", "frequency": freq, "center_deflection": amp},
    }
    if material != "ground":
        surface["lobe_width"] = lobe
    return scene_from_table(
        {
            "sun": {"inclination": sun_inc, "azimuth": np.pi},
            "sensor": {"inclination": min(np.pi / 2, sun_inc + view_off), "azimuth": az_off},
            "sampling": {"fs": 400.0, "duration": 0.1},
            "footprint": {"x": [fx * size, fx * size + size], "y": [fy * size, fy * size + size], "resolution": 14},
            "surfaces": {"s": surface},
        }
    )


@settings(max_examples=25, deadline=None)
@given(
    sun_inc=st.floats(0.05, 1.5),
    view_off=st.floats(-0.03, 0.03),
    az_off=st.floats(-0.02, 0.02),
    material=st.sampled_from(["steel", "glass", "aluminium", "ground"]),
    lobe=st.floats(0.005, 0.05),
    amp=st.floats(1e-7, 1e-2),
    freq=st.floats(5.0, 150.0),
    fx=st.floats(-1.0, 0.0),
    fy=st.floats(-1.0, 0.0),
    size=st.floats(1.0, 50.0),
)
def test_fast_matches_dense_on_random_scenes(sun_inc, view_off, az_off, material, lobe, amp, freq, fx, fy, size):
    s = random_scene(sun_inc, view_off, az_off, material, lobe, amp, freq, fx, fy, size)
    ref = pixel_signal(s)
    rtol = 1e-4
    fast = compile_scene(s, rtol=rtol).signal()
    # dense float64 cannot resolve AC parts below ~1e-15 of the mean: allow that floor
    floor = 1e3 * np.finfo(float).eps * np.abs(ref).max()
    assert np.abs(fast - ref).max() <= rtol * np.ptp(ref) + floor

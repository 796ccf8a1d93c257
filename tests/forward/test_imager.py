"""The imager: every pixel of the cube is the single-pixel render of that pixel's footprint."""

import dataclasses

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from forward.errors import SceneError
from forward.imager import pixel_grid, pixel_scene, render_cube
from forward.motion.base import ModalMotion
from forward.reduce import DEFAULT_RTOL
from forward.render import pixel_signal
from forward.scene import MEMORY_LIMIT_ENV, Footprint
from forward.scene_file import load_scene
from forward.sensor import observe
from tests.conftest import SCENES

# the sec. 4.2 roof ([-25, 25]^2) inside a field of view of [-40, 40]^2: 10 x 10 pixels of 8 m, 16
# subpixels of 0.5 m per side, so the roof's edges (15 m = 30 subpixels from the view's edge) fall
# on the subpixel lattice and edge pixels hold 1/8 (a side) or 1/64 (a corner) of roof
VIEW = ("footprint.x=[-40, 40]", "footprint.y=[-40, 40]")
FRAME = (*VIEW, "sampling.duration=2")
ELASTIC = (*VIEW, "footprint.resolution=16")  # 8 x 8 pixels of 10 m: pixel edges at x = 0


def motion_stream(seed):
    """The motions' stream of `observe` and `render_cube` for `seed`."""
    return np.random.SeedSequence(seed).spawn(2)[0]


def relative_error(got, ref):
    return np.abs(got - ref).max() / np.ptp(ref)


def overlap(a, b):
    return max(0.0, min(a[1], b[1]) - max(a[0], b[0]))


@pytest.fixture(scope="module")
def frame_cube():
    scene = load_scene(SCENES / "roof_frame.toml", list(FRAME))[0]
    return scene, render_cube(scene, 10, 10, seed=3)


@pytest.mark.parametrize(
    "iy, ix, roof",
    [(5, 5, 1.0), (5, 1, 1 / 8), (1, 1, 1 / 64), (8, 4, 1 / 8), (0, 0, 0.0)],
    ids=["interior", "left edge", "corner", "top edge", "background"],
)
def test_rigid_roof_pixels_are_their_single_pixel_render(frame_cube, iy, ix, roof):
    scene, cube = frame_cube
    one = pixel_scene(scene, cube.grid, iy, ix)
    assert cube.coverage["roof"][iy, ix] == roof and cube.coverage["background"][iy, ix] == 1 - roof
    ref = pixel_signal(one, seed=motion_stream(3))  # dense: every subpixel at every sample
    got = cube.intensity_clean[:, iy, ix]
    if roof == 0:  # the static ground: one facet value, exact
        np.testing.assert_allclose(got, ref, rtol=1e-14)
        return
    # a rigid roof is one normal: its facet signal at that normal is exact (measured 3e-13 of
    # peak-to-peak, the dense sum's roundoff), far inside the compiler's contract of rtol
    assert relative_error(got, ref) <= 1e-9
    assert relative_error(got, observe(one, seed=3).intensity_clean) <= DEFAULT_RTOL  # the fast single pixel


def test_rigid_roof_is_evaluated_once_for_all_its_pixels(frame_cube):
    _, cube = frame_cube
    assert cube.evaluation == {"roof": {"rigid": 64}, "background": {"static": 64}}  # 28 pixels see both
    inside = cube.intensity_clean[:, 2:8, 2:8]  # the pixels wholly on the roof see the same facet
    assert np.all(inside == inside[:, :1, :1])


def test_coverage_is_the_area_fraction_of_each_pixel(frame_cube):
    scene, cube = frame_cube
    g = cube.grid
    roof = scene.surfaces[0]
    area = np.array(
        [
            [overlap(roof.y, g.y_edges[j : j + 2]) * overlap(roof.x, g.x_edges[i : i + 2]) for i in range(10)]
            for j in range(10)
        ]
    ) / (8.0 * 8.0)
    np.testing.assert_array_equal(cube.coverage["roof"], area)  # exact: the edges lie on the subpixel lattice
    np.testing.assert_array_equal(cube.coverage["roof"] + cube.coverage["background"], 1.0)


@given(
    nx=st.integers(1, 6),
    ny=st.integers(1, 6),
    r=st.integers(1, 9),
    x0=st.floats(-60, 10),
    y0=st.floats(-60, 10),
    w=st.floats(1, 120),
    pick=st.integers(0, 35),
)
def test_coverage_counts_the_single_pixel_subpixels(nx, ny, r, x0, y0, w, pick):
    """For any view and pixel count, a pixel's coverage is what its single-pixel scene's subpixels see."""
    view = (f"footprint.x=[{x0!r}, {x0 + w!r}]", f"footprint.y=[{y0!r}, {y0 + w / 2!r}]", "sampling.duration=0.05")
    s = load_scene(SCENES / "roof_frame.toml", list(view))[0]
    cube = render_cube(s, nx, ny, seed=0, subpixels=r)
    iy, ix = divmod(pick % (nx * ny), nx)
    fp = cube.grid.footprint(iy, ix)
    x, y = Footprint(fp.x, fp.y, r).subpixels()
    assert cube.coverage["roof"][iy, ix] == np.count_nonzero(s.owners(x, y) == 0) / r**2


def test_one_pixel_is_the_scene_itself(scene):
    s = scene("roof_elastic", "footprint.resolution=32", "sampling.duration=0.1")
    cube = render_cube(s, 1, 1, seed=5)
    assert cube.grid.footprint(0, 0) == s.footprint
    ref = pixel_signal(s, seed=motion_stream(5))
    assert relative_error(cube.intensity_clean[:, 0, 0], ref) <= DEFAULT_RTOL


@pytest.fixture(scope="module")
def elastic():
    scene = load_scene(SCENES / "roof_elastic.toml", list(ELASTIC))[0]
    return scene, render_cube(scene, 8, 8, seed=1)


def test_elastic_roof_pixels_meet_rtol_against_the_dense_render(elastic):
    scene, cube = elastic
    kinds = cube.evaluation["roof"]
    assert set(kinds) == {"taylor2", "chebyshev"} and sum(kinds.values()) == 36  # both per-pixel models used
    for iy in range(1, 7):
        for ix in range(1, 7):
            ref = pixel_signal(pixel_scene(scene, cube.grid, iy, ix), seed=motion_stream(1))
            err = np.abs(cube.intensity_clean[:, iy, ix] - ref).max()
            # the compiler's contract (measured: at most 9.4e-6 of p-p, the same as `observe` of
            # each pixel), and the cube's own error estimate holds
            assert err <= DEFAULT_RTOL * np.ptp(ref), (iy, ix)
            assert err <= cube.error_bound[iy, ix] * 1.01 + 1e-12 * np.abs(ref).max(), (iy, ix)


def test_elastic_roof_pixels_on_opposite_sides_flicker_in_antiphase(elastic):
    _, cube = elastic
    ac = cube.intensity_clean - cube.intensity_clean.mean(axis=0)
    # sun and sensor in the x-z plane: the signal follows h_x, which changes sign across x = 0
    for iy in (2, 4):
        left, right = ac[:, iy, 2], ac[:, iy, 5]
        assert np.corrcoef(left, right)[0, 1] < -0.99
        assert np.corrcoef(left, ac[:, iy, 3])[0, 1] > 0.99  # the same side: in phase


def test_elastic_dense_path_is_the_dense_render(scene):
    s = scene("roof_elastic", *ELASTIC, "sampling.duration=0.05")
    cube = render_cube(s, 4, 4, seed=0, rtol=None)
    assert cube.evaluation["roof"] == {"dense": 16}
    ref = pixel_signal(pixel_scene(s, cube.grid, 1, 2), seed=motion_stream(0))
    assert relative_error(cube.intensity_clean[:, 1, 2], ref) <= 1e-11  # the same sum in another order


def test_two_coordinate_chebyshev_and_dense_fallbacks_meet_rtol(scene):
    """Ground waves large enough that the Taylor model fails: one line (2 coordinates) goes to a 2-D
    Chebyshev interpolant, two lines (4) to every subpixel."""
    base = ("footprint.resolution=8", "footprint.x=[-50, 50]", "footprint.y=[-50, 50]", "sampling.duration=0.05")
    for lines, kind in (("[40]", "chebyshev"), ("[40, 45]", "dense")):
        amps = "[0.3]" if lines == "[40]" else "[0.3, 0.3]"
        s = scene("ground_rayleigh", *base, "sun.inclination=0.3", f"{KG}frequency={lines}", f"{KG}amplitude={amps}")
        cube = render_cube(s, 3, 3, seed=0)
        assert cube.evaluation["ground"] == {kind: 9}
        for iy, ix in ((0, 0), (1, 2)):
            ref = pixel_signal(pixel_scene(s, cube.grid, iy, ix), seed=motion_stream(0))
            assert relative_error(cube.intensity_clean[:, iy, ix], ref) <= DEFAULT_RTOL


KG = "surfaces.ground.motion."


def test_noise_is_independent_per_pixel_and_reproducible(scene):
    s = scene("roof_frame", *VIEW, "sampling.duration=10", "noise.sigma=0.6")
    a = render_cube(s, 4, 4, seed=7)
    b = render_cube(s, 4, 4, seed=7)
    np.testing.assert_array_equal(a.intensity, b.intensity)
    assert not np.array_equal(a.intensity, render_cube(s, 4, 4, seed=8).intensity)
    noise = (a.intensity - a.intensity_clean).reshape(a.shape[0], -1)  # 2000 samples x 16 pixels
    # sample sd of 2000 normal values: relative standard error 1/sqrt(2 * 2000) = 1.6 %; 5 sigma
    np.testing.assert_allclose(noise.std(axis=0), 0.6, rtol=5 / np.sqrt(2 * noise.shape[0]))
    corr = np.corrcoef(noise.T)[np.triu_indices(16, 1)]
    # independent streams: each correlation ~ N(0, 1/2000); max of 120 within 4.5 sigma
    assert np.abs(corr).max() < 4.5 / np.sqrt(noise.shape[0])


def test_one_adc_range_for_the_whole_sensor(scene):
    s = scene("roof_frame", *VIEW, "sampling.duration=0.5", "noise.sigma=0.6", "noise.adc_bits=10")
    cube = render_cube(s, 5, 5, seed=1)
    step = 2 * cube.intensity_clean.max() / (2**10 - 1)  # [noise] adc_full_scale = 0: twice the cube's max
    counts = cube.intensity / step
    # every pixel, the dark ground (clean ~0.3) as the bright roof (~540), on the one grid of counts
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)


@pytest.mark.parametrize(
    "kwargs, key",
    [
        ({"nx": 0, "ny": 4}, "nx: 0 is outside the allowed range [1, 4096]"),
        ({"nx": 4, "ny": 5000}, "ny: 5000 is outside the allowed range [1, 4096]"),
        ({"nx": 2.5, "ny": 4}, "nx: must be an integer"),
        ({"nx": True, "ny": 4}, "nx: must be an integer"),
        ({"nx": 4, "ny": 4, "rtol": 0.0}, "rtol: 0.0 is outside the allowed range (0, inf)"),
        ({"nx": 4, "ny": 4, "seed": -1}, "seed: -1 is outside the allowed range [0, 2^32)"),
    ],
)
def test_bad_arguments_are_one_line_errors(scene, kwargs, key):
    with pytest.raises(SceneError) as exc:
        render_cube(scene("roof_frame", "sampling.duration=0.1"), **kwargs)
    assert key in str(exc.value) and "\n" not in str(exc.value)


def test_memory_is_checked_before_the_cube_is_allocated(scene, monkeypatch):
    s = scene("roof_frame")  # 4000 samples
    monkeypatch.setenv(MEMORY_LIMIT_ENV, str(50 * 2**20))
    with pytest.raises(SceneError, match=r"4000 samples x 16384 pixels .* reduce .*nx, ny"):
        render_cube(s, 128, 128)
    assert render_cube(s, 8, 8).shape == (4000, 8, 8)  # well within


def test_grid_edges_and_centres(scene):
    g = pixel_grid(scene("roof_frame", *VIEW), 4, 2)
    np.testing.assert_array_equal(g.x_edges, [-40, -20, 0, 20, 40])
    np.testing.assert_array_equal(g.y, [-20, 20])
    assert g.footprint(1, 3) == Footprint((20.0, 40.0), (0.0, 40.0), 16)


class Hinge(ModalMotion):
    """A tilt the same everywhere at x < 0 and growing with x beyond: rigid on part of the view only."""

    def shapes(self, x, y):
        return np.stack([np.where(x < 0, 1.0, 1.0 + x / 10), np.zeros_like(y)])[None]

    def coefficients(self, t):
        return 2e-3 * np.sin(2 * np.pi * 5 * np.asarray(t))[:, None]


def test_blocks_of_one_pixel_and_a_surface_rigid_in_the_first_blocks(scene, monkeypatch):
    """One pixel per block of subpixels; the first pixels see the uniform part of the motion (it
    looks rigid until a later block), so their moments are formed from the one shape afterwards."""
    import forward.imager

    monkeypatch.setattr(forward.imager, "BLOCK_POINTS", 64)  # 8 x 8 subpixels: one pixel
    s = scene("roof_frame", "footprint.resolution=8", "footprint.x=[-20, 20]", "footprint.y=[-20, 20]")
    roof = dataclasses.replace(s.surfaces[0], motion=Hinge())
    s = dataclasses.replace(s, surfaces=(roof,), sampling=dataclasses.replace(s.sampling, duration=0.2))
    cube = render_cube(s, 4, 4, seed=0)
    assert sum(cube.evaluation["roof"].values()) == 16 and "rigid" not in cube.evaluation["roof"]
    for iy, ix in ((0, 0), (0, 1), (3, 2), (3, 3)):
        ref = pixel_signal(pixel_scene(s, cube.grid, iy, ix), seed=motion_stream(0))
        assert relative_error(cube.intensity_clean[:, iy, ix], ref) <= DEFAULT_RTOL, (iy, ix)

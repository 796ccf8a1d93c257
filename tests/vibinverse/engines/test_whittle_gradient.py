"""`ModalModel.whittle_gradient`'s analytic parts (`block_gradient`, `line_gradient`) against
finite differences of the density and the lines' transform, and the whole gradient against central
differences of Whittle's ln L and against the forward-difference gradient it replaced."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vibinverse.engines.whittle import (
    Periodogram,
    block_gradient,
    dot,
    line_gradient,
    spectral_density,
)
from vibinverse.io.series import Series
from vibinverse.kalman import oscillator_fill
from vibinverse.models.modal import ModalModel


def ordinates(m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    w = 2.0 * np.pi * np.arange(1, m // 2 + 1) / m
    return np.cos(w), np.sin(w), 4.0 * np.sin(0.5 * w) ** 2


def block_density(phi, q, h, o, size, diff, m=4000):
    cw, sw, c = ordinates(m)
    out = np.empty(cw.size)
    spectral_density(cw, sw, c, diff, phi, q, h, 0.0, np.array([o]), np.array([size]), out)
    return out


def entry_positions(o: int, size: int) -> list[tuple[int, int, int]]:
    """(table 0 phi / 1 q, row, column) of each entry `block_gradient` reports."""
    if size == 1:
        return [(0, o, o), (1, o, o)]
    return [(0, o, o), (0, o, o + 1), (0, o + 1, o), (0, o + 1, o + 1), (1, o, o), (1, o, o + 1), (1, o + 1, o + 1)]


def two_by_two(dt: float, zeta: float) -> tuple[np.ndarray, np.ndarray]:
    w = 2 * math.pi * 3.0
    phi, q = np.zeros((1, 3, 3)), np.zeros((1, 3, 3))
    oscillator_fill(w, zeta * w, 4 * zeta * w**3 * 1.3**2, np.array([dt]), phi[:, 1:, 1:], q[:, 1:, 1:], 0)
    return phi[0], q[0]


@pytest.mark.parametrize("diff", [0, 1])
@pytest.mark.parametrize("case", ["oscillator", "oscillator_seen_twice", "light_damping", "ou", "walk", "no_noise"])
def test_block_gradient_is_the_density_slope_in_each_entry(case, diff):
    """sum_j slope_j d f_j / d entry equals central differences of `spectral_density`'s share of
    the block, entry by entry (Q's off-diagonal entry moved on both sides: Q stays symmetric)."""
    rng = np.random.default_rng(7)
    h = np.array([0.0, 1.0, 0.0])
    if case.startswith("oscillator") or case == "light_damping":
        phi, q = two_by_two(0.01, 1e-3 if case == "light_damping" else 0.05)
        o, size = 1, 2
        if case == "oscillator_seen_twice":
            h[2] = -0.4
    else:
        phi, q = np.zeros((3, 3)), np.zeros((3, 3))
        o, size = 1, 1
        phi[1, 1] = {"ou": math.exp(-0.01 / 0.2), "walk": 1.0, "no_noise": 0.97}[case]
        q[1, 1] = 0.0 if case == "no_noise" else 0.04
    slope = rng.normal(size=2000)
    cw, sw, c = ordinates(4000)
    got = np.empty(7)
    block_gradient(cw, sw, c, diff, phi, q, h, o, size, slope, got)
    for i, (table, row, col) in enumerate(entry_positions(o, size)):
        # the share is linear in Q: any step; Phi's entries by 1e-7 (a light damping's peak is narrow)
        step = 1e-2 * max(np.abs(q).max(), 1e-3) if table else 1e-7 * max(abs(phi[row, col]), 1e-3)
        lls = []
        for sign in (1.0, -1.0):
            p, qq = phi.copy(), q.copy()
            moved = (p, qq)[table]
            moved[row, col] += sign * step
            if table == 1:
                moved[col, row] = moved[row, col]
            lls.append(dot(slope, block_density(p, qq, h, o, size, diff)))
        num = (lls[0] - lls[1]) / (2 * step)
        assert got[i] == pytest.approx(num, rel=1e-5, abs=1e-7 * np.abs(slope).sum()), (case, i)


@pytest.mark.parametrize("diff", [0, 1])
@pytest.mark.parametrize("where", ["between", "on", "1e-9 beside", "3e-7 beside", "near zero", "near nyquist"])
def test_line_gradient_is_the_transform_slope(where, diff):
    """(X, dX / d theta, dX / d psi) of the unit line, dotted with weights, equal the transform and
    central differences of it (`line_transform`), on an ordinate (its pole branch), next to one on
    either side of the branch, and near the ends."""
    rng = np.random.default_rng(3)
    p = Periodogram(6001, diff)
    m = p.m
    on = 2 * np.pi * 411 / m
    theta = {
        "between": 0.7,
        "on": on,
        "1e-9 beside": on + 1e-9,
        "3e-7 beside": on - 3e-7,
        "near zero": 0.4 / m,
        "near nyquist": np.pi - 0.3 / m,
    }[where]
    psi = 0.9
    wre, wim = rng.normal(size=p.c.size), rng.normal(size=p.c.size)
    got = np.empty(3)
    line_gradient(p.cw, p.sw, m, diff, theta, psi, wre, wim, out := got)

    def weighted(th, ps):
        x = p.line_transform(th, ps, 1.0)
        return dot(wre, x.real) + dot(wim, x.imag)

    assert got[0] == pytest.approx(weighted(theta, psi), rel=1e-9, abs=1e-9 * m)
    scale = m * np.abs(wre).sum() / 1e3  # the transform's size, m, against the weights
    ht = 1e-4 / m
    assert out[1] == pytest.approx(
        (weighted(theta + ht, psi) - weighted(theta - ht, psi)) / (2 * ht), rel=1e-5, abs=1e-6 * m * scale
    )
    hp = 1e-5
    assert out[2] == pytest.approx(
        (weighted(theta, psi + hp) - weighted(theta, psi - hp)) / (2 * hp), rel=1e-6, abs=1e-9 * scale
    )


MODE = {"modes[0].frequency": 3.0, "modes[0].damping_ratio": 0.05, "modes[0].rms": 1.3}
LINES = {
    "lines[0].frequency": 2.913,
    "lines[0].amplitude": 0.2,
    "lines[0].phase": -1.0,
    "lines[1].frequency": 7.3071,
    "lines[1].amplitude": 0.4,
    "lines[1].phase": 0.5,
}
CASES = {
    "one mode": ({"modes": 1, "lines": 2}, {}),
    "three modes": (
        {"modes": 3, "lines": 2},
        {
            "modes[1].frequency": 5.1,
            "modes[1].damping_ratio": 0.02,
            "modes[1].rms": 0.5,
            "modes[2].frequency": 11.0,
            "modes[2].damping_ratio": 0.1,
            "modes[2].rms": 0.8,
        },
    ),
    "random walk": ({"modes": 1, "lines": 2, "drift": True}, {"drift.rate": 0.5}),
    "ar1": ({"modes": 1, "lines": 2, "noise": "ar1"}, {"ar.rms": 0.6, "ar.time": 0.05}),
    "line on an ordinate": ({"modes": 1, "lines": 2}, {"lines[1].frequency": 1752 / 240}),  # m = 24,000, 0.01 s
    "damping 1e-4": ({"modes": 1, "lines": 2}, {"modes[0].damping_ratio": 1e-4}),
    "damping 0.9": ({"modes": 1, "lines": 2}, {"modes[0].damping_ratio": 0.9}),
}


def case_model(case: str) -> tuple[ModalModel, dict[str, float]]:
    """A 24,001-sample record (0.01 s steps from 3.7 s) drawn from the case's model, and values near
    its truth (the mode's rms and the noise a little off)."""
    spec, extra = CASES[case]
    truth = {"level": 2.0, **MODE, **LINES, "noise.sigma": 0.3, **extra}
    t = 3.7 + 0.01 * np.arange(24_001)
    model = ModalModel({"modal": spec}, Series(t, np.zeros(t.size), "zeros"))
    y = model.replicate(truth, np.random.default_rng(sorted(CASES).index(case)))
    model = ModalModel({"modal": spec}, Series(t, y, case))
    assert model.spectral is not None and model.spectral.m == 24_000
    return model, {**truth, "modes[0].rms": 1.3 * 1.03, "noise.sigma": 0.3 * 0.98}


@pytest.mark.parametrize("bins", [1, 4])
@pytest.mark.parametrize("case", list(CASES))
def test_analytic_whittle_gradient_is_the_slope_of_the_likelihood(case, bins):
    """The gradient equals central differences of Whittle's ln L (rtol 1e-4) in every parameter
    (it also matched the forward-difference gradient it replaced to 3.3e-5 when it landed), with
    the ordinates each their own and grouped 4 at a time (the order search's `search_bins`)."""
    model, values = case_model(case)
    if bins > 1:
        model.start_engine(bins)
    assert set(model.fittable()) == set(values)
    slope = model.whittle_gradient(values)
    assert set(slope) == set(values)
    for name, d in slope.items():
        v = values[name]
        # steps on each parameter's own scale: 1e-4 of a Fourier bin, 1e-3 of a mode's half-width
        if name.startswith("lines") and name.endswith(".frequency"):
            h = 1e-4 / model.span
        elif name.endswith(".frequency"):
            h = 1e-3 * values[name.replace("frequency", "damping_ratio")] * v
        else:
            h = 1e-6 * max(abs(v), 1.0 if name.endswith(".phase") else model.sd if name == "level" else 1e-12)
        up, down = model.log_likelihood({**values, name: v + h}), model.log_likelihood({**values, name: v - h})
        num = (up - down) / (2 * h)
        assert d == pytest.approx(num, rel=1e-4, abs=1e-3), (case, name)


def test_whittle_gradient_of_some_names_is_the_whole_ones():
    model, values = case_model("random walk")
    whole = model.whittle_gradient(values)
    some = model.whittle_gradient(values, ["drift.rate", "lines[1].phase", "noise.sigma", "level"])
    assert some == {n: whole[n] for n in some}

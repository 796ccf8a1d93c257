"""Ground Rayleigh waves from a buried vibrating structure (paper sec. 2.2.3, eqs. (17)-(20)).

The line of 3-D point sources (19) has a closed form, since the integral of
e^{ik sqrt(r^2+z^2)} / sqrt(r^2+z^2) dz over the line is i pi H0^(1)(kr). Hence

    u_G2D(r, t) = pi [J0(kr) sin(wt) - Y0(kr) cos(wt)]          (closed form of (19))

Continuity with the piston u = A0 cos(wt - phi) for r < R (eq. (20)) fixes, in closed form,

    C = A0 / (pi |H0(kR)|),   phi = atan2(J0(kR), -Y0(kR)).

For r >= R the surface slope is du/dr = C pi k [-J1(kr) sin(wt) + Y1(kr) cos(wt)] along r-hat;
inside R the piston is flat (slope 0). Several frequencies superpose, each with an optional phase
(wt -> wt + phase: the source's time origin, which a fit of measured data needs). The slope field
is A0 sin(wt + phase) * shape_s + A0 cos(wt + phase) * shape_c per frequency, shapes per unit A0:
a modal motion with two modes each, whose amplitudes live in the modal coordinates.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.integrate import quad
from scipy.special import j0, j1, y0, y1

from forward.errors import SceneError
from forward.motion.base import ModalMotion
from forward.validation import Table


def green_2d(r: NDArray[np.float64], t: NDArray[np.float64], k: float, omega: float) -> NDArray[np.float64]:
    """Closed form of eq. (19): pi [J0(kr) sin(wt) - Y0(kr) cos(wt)], broadcast over r and t."""
    kr = k * np.asarray(r, dtype=float)
    wt = omega * np.asarray(t, dtype=float)
    return np.pi * (j0(kr) * np.sin(wt) - y0(kr) * np.cos(wt))


def green_2d_quadrature(r: float, t: float, k: float, omega: float) -> float:
    """Eq. (19) by quadrature: the test oracle for `green_2d`, not for production.

    With rho = r + w the integral is 2 int_0^inf cos(k(r + w) - wt) / sqrt(w (w + 2r)) dw, which
    converges only conditionally. The inverse-square-root singularity at w = 0 is integrated with
    QUADPACK's algebraic weight on [0, a]; the oscillatory tail on [a, inf) with its Fourier-integral
    rule (QAWF, with extrapolation over cycles).
    """
    import warnings

    from scipy.integrate import IntegrationWarning

    a = 2 * np.pi / k
    phase = k * r - omega * t

    def part(trig: str) -> float:
        head = quad(
            lambda w: (np.cos if trig == "cos" else np.sin)(k * w) / np.sqrt(w + 2 * r),
            0.0,
            a,
            weight="alg",
            wvar=(-0.5, 0.0),
            epsabs=0.0,
            epsrel=1e-13,
            limit=200,
        )[0]
        tail = quad(
            lambda w: 1.0 / np.sqrt((w + a) * (w + a + 2 * r)),
            0.0,
            np.inf,
            weight=trig,
            wvar=k,
            epsabs=1e-15,
            limlst=200,
        )[0]
        # shift the tail's oscillation back by k a = 2 pi: cos(k(w + a)) = cos(k w)
        return head + tail

    with warnings.catch_warnings():  # QAWF flags the slow 1/w decay, yet converges (tested to 1e-13)
        warnings.simplefilter("ignore", IntegrationWarning)
        return 2.0 * (np.cos(phase) * part("cos") - np.sin(phase) * part("sin"))


def continuity(radius: float, k: float, amplitude: float) -> tuple[float, float]:
    """(C, phi) of eq. (20): continuity of u at r = R for all t, in closed form."""
    j, y = j0(k * radius), y0(k * radius)
    return amplitude / (np.pi * np.hypot(j, y)), float(np.arctan2(j, -y))


class RayleighMotion(ModalMotion):
    """Ground displacement (20) about `center`: piston of radius R inside, outgoing waves outside.

    frequencies (Hz), amplitudes A0 (m) at the piston, wave_speed v_R (m/s), phases (rad, default 0).
    """

    line_keys = ("frequency", "amplitude", "phase")

    def __init__(
        self,
        center: tuple[float, float],
        radius: float,
        wave_speed: float,
        frequencies: NDArray[np.float64],
        amplitudes: NDArray[np.float64],
        phases: NDArray[np.float64] | None = None,
    ):
        if not radius > 0:
            raise SceneError(f"rayleigh.radius: {radius:g} is outside the allowed range (0, inf)")
        if not wave_speed > 0:
            raise SceneError(f"rayleigh.wave_speed: {wave_speed:g} is outside the allowed range (0, inf)")
        self.center = np.asarray(center, dtype=float)
        self.radius = float(radius)
        self.wave_speed = float(wave_speed)
        self.frequencies = np.atleast_1d(np.asarray(frequencies, dtype=float))
        self.amplitudes = np.atleast_1d(np.asarray(amplitudes, dtype=float))
        self.phases = (
            np.zeros(self.frequencies.size) if phases is None else np.atleast_1d(np.asarray(phases, dtype=float))
        )
        if not (self.frequencies.size == self.amplitudes.size == self.phases.size):
            raise SceneError(
                f"rayleigh: needs one amplitude and phase per frequency ({self.frequencies.size}), "
                f"got {self.amplitudes.size} and {self.phases.size}"
            )
        self.omega = 2 * np.pi * self.frequencies
        self.k = self.omega / self.wave_speed
        self.c_unit = np.array([continuity(self.radius, k, 1.0)[0] for k in self.k])  # C per unit A0
        self.c = self.c_unit * self.amplitudes

    def wavelength(self) -> NDArray[np.float64]:
        return self.wave_speed / self.frequencies

    def displacement(self, r: NDArray[np.float64], t: NDArray[np.float64]) -> NDArray[np.float64]:
        """u(r, t) of eq. (20), shape broadcast(r, t); sums over frequencies."""
        r = np.asarray(r, dtype=float)
        t = np.asarray(t, dtype=float)
        out = 0.0
        for k, w, c, a, ph in zip(self.k, self.omega, self.c, self.amplitudes, self.phases):
            phi = continuity(self.radius, k, a)[1]
            ts = t + ph / w
            out = out + np.where(
                r < self.radius, a * np.cos(w * ts - phi), c * green_2d(np.maximum(r, self.radius), ts, k, w)
            )
        return out

    def radial_slope(self, r: NDArray[np.float64], t: NDArray[np.float64]) -> NDArray[np.float64]:
        """du/dr; zero inside the piston."""
        r = np.asarray(r, dtype=float)
        t = np.asarray(t, dtype=float)
        out = 0.0
        for k, w, c, ph in zip(self.k, self.omega, self.c, self.phases):
            kr = k * np.maximum(r, self.radius)
            d = c * np.pi * k * (-j1(kr) * np.sin(w * t + ph) + y1(kr) * np.cos(w * t + ph))
            out = out + np.where(r < self.radius, 0.0, d)
        return out

    def shapes(self, x, y):
        dx = np.asarray(x, dtype=float) - self.center[0]
        dy = np.asarray(y, dtype=float) - self.center[1]
        r = np.hypot(dx, dy)
        outside = r >= self.radius
        rs = np.where(outside, r, 1.0)
        ux, uy = np.where(outside, dx / rs, 0.0), np.where(outside, dy / rs, 0.0)
        modes = []
        for k, c in zip(self.k, self.c_unit):
            kr = k * np.where(outside, r, self.radius)
            g_sin, g_cos = -c * np.pi * k * j1(kr), c * np.pi * k * y1(kr)
            modes += [np.stack([g_sin * ux, g_sin * uy]), np.stack([g_cos * ux, g_cos * uy])]
        return np.array(modes)

    def shape_key(self) -> tuple:
        return ("rayleigh", *self.center, self.radius, self.wave_speed, *self.frequencies)

    def coefficients(self, t):
        wt = np.outer(np.asarray(t, dtype=float), self.omega) + self.phases
        q = np.stack([np.sin(wt), np.cos(wt)], axis=2) * self.amplitudes[:, None]  # (T, F, 2)
        return q.reshape(wt.shape[0], -1)

    def max_frequency(self) -> float:
        return float(self.frequencies.max())

    @classmethod
    def from_table(cls, t: Table, x_range: tuple[float, float], y_range: tuple[float, float]) -> RayleighMotion:
        """Scene table: center [x, y] (m), radius R (m), wave_speed v_R (m/s), frequency and
        amplitude, optional phase (numbers or equal-length lists; Hz, m, rad)."""
        center = t.numbers("center", [0.0, 0.0])
        if len(center) != 2:
            raise SceneError(f"{t.path('center')}: must be [x, y] in m")
        radius = t.number("radius", lo=0.0, lo_open=True)
        speed = t.number("wave_speed", lo=0.0, lo_open=True)
        freqs = np.array(t.numbers("frequency", lo=0.0, lo_open=True))
        amps = np.array(t.numbers("amplitude", lo=0.0))
        if freqs.size == 0 or freqs.size != amps.size:
            raise SceneError(
                f"{t.path('amplitude')}: needs one amplitude per frequency ({freqs.size}), got {amps.size}"
            )
        phases = np.array(t.numbers("phase", [0.0] * freqs.size))
        if phases.size != freqs.size:
            raise SceneError(f"{t.path('phase')}: needs one phase per frequency ({freqs.size}), got {phases.size}")
        return cls(center, radius, speed, freqs, amps, phases)

"""Building-frame resonance model (paper sec. 2.2.2, eqs. (11)-(16)).

A rigid roof (mass M, sides LX x LY, uniform-plate inertia) rests on four corner spring-dashpots:
k1, b1 vertical, k2, b2 lateral. Each spring's base may move: the drive (11) moves one corner's base
in a circle, and the noise is Gaussian white base motion (zero-order hold at the sample rate) of
RMS `noise_rms` at every corner and axis.

The paper's Euler angles are singular at theta = 0, i.e. at the flat roof, the equilibrium. The
nonlinear model here integrates the attitude as a unit quaternion with body rates (Euler's equations
(15)), which has no singularity. For inference and fast simulation, the model is linearized about
the equilibrium in generalized coordinates q = (x, y, z, rx, ry, rz) (small rotations about the world
axes). With four identical corners symmetric about the centre, these six coordinates decouple
exactly into the paper's modes: lateral (x, y), vertical (z), tilt (rx, ry) and twist (rz).

Noise forcing acts through the springs. A zero-order-hold base displacement has impulsive velocity,
so its dashpot force is left out: at the tilt resonance b1 omega / k1 = 0.016 for the paper's
values, i.e. a ~2 % part of the noise force. The deterministic drive acts through springs and
dashpots.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import expm, solve_discrete_lyapunov

from forward.errors import SceneError
from forward.motion.base import ModalMotion, Motion
from forward.validation import Table

COORDINATES = ("x", "y", "z", "rx", "ry", "rz")
MODE_OF_COORDINATE = {"x": "lateral", "y": "lateral", "z": "vertical", "rx": "tilt", "ry": "tilt", "rz": "twist"}
CORNER_SIGNS = ((1, 1), (-1, 1), (-1, -1), (1, -1))  # corner j sits at (sx LX/2, sy LY/2)


@dataclass(frozen=True)
class FrameParameters:
    """Physical parameters: mass M (kg), roof sides lx, ly (m), corner stiffness k1 (vertical), k2
    (lateral) in N/m and damping b1, b2 in N s/m. The paper: M = 1, k1 = (2 pi)^2, k2 = 4 (2 pi)^2,
    b1 = b2 = 0.05."""

    mass: float
    lx: float
    ly: float
    k1: float
    b1: float
    k2: float
    b2: float

    def __post_init__(self):
        for name in ("mass", "lx", "ly", "k1", "k2"):
            if not getattr(self, name) > 0:
                raise SceneError(f"frame.{name}: {getattr(self, name):g} is outside the allowed range (0, inf)")
        for name in ("b1", "b2"):
            if not getattr(self, name) >= 0:
                raise SceneError(f"frame.{name}: {getattr(self, name):g} is outside the allowed range [0, inf)")

    @property
    def inertia(self) -> NDArray[np.float64]:
        """Principal moments (I1, I2, I3) of a uniform plate, as below eq. (16)."""
        m, lx, ly = self.mass, self.lx, self.ly
        return np.array([m * ly**2 / 12, m * lx**2 / 12, m * (lx**2 + ly**2) / 12])

    @property
    def generalized_mass(self) -> NDArray[np.float64]:
        return np.concatenate([np.full(3, self.mass), self.inertia])

    def corners(self) -> NDArray[np.float64]:
        """Corner positions in the body frame, shape (4, 3)."""
        return np.array([[sx * self.lx / 2, sy * self.ly / 2, 0.0] for sx, sy in CORNER_SIGNS])

    @property
    def stiffness(self) -> NDArray[np.float64]:
        return np.array([self.k2, self.k2, self.k1])

    @property
    def damping(self) -> NDArray[np.float64]:
        return np.array([self.b2, self.b2, self.b1])

    def modal(self) -> dict[str, tuple[float, float]]:
        """{mode: (resonance frequency in Hz, damping ratio)} for lateral, vertical, tilt, twist."""
        lin = linearize(self)
        out = {}
        for i, c in enumerate(COORDINATES):
            out.setdefault(MODE_OF_COORDINATE[c], (lin.frequencies_hz[i], lin.damping_ratios[i]))
        return out

    @classmethod
    def from_modal(cls, lx: float, ly: float, mass: float = 1.0, **modes: tuple[float, float]) -> FrameParameters:
        """Physical parameters from (frequency Hz, damping ratio) of one vertical-type mode
        (`vertical` or `tilt`) and one lateral-type mode (`lateral` or `twist`).

        With corner springs on a uniform plate the pairs are tied: f_tilt = sqrt(3) f_vertical,
        zeta_tilt = sqrt(3) zeta_vertical, and the same for twist and lateral.
        """
        vert = [k for k in ("vertical", "tilt") if k in modes]
        lat = [k for k in ("lateral", "twist") if k in modes]
        if len(vert) != 1 or len(lat) != 1 or len(modes) != 2:
            raise SceneError(
                "frame: give exactly one of vertical|tilt and one of lateral|twist (frequency, damping ratio)"
            )
        k1, b1 = _spring_from_mode(mass, *modes[vert[0]], 4.0 if vert[0] == "vertical" else 12.0, vert[0])
        k2, b2 = _spring_from_mode(mass, *modes[lat[0]], 4.0 if lat[0] == "lateral" else 12.0, lat[0])
        return cls(mass, lx, ly, k1, b1, k2, b2)


def _spring_from_mode(mass: float, f: float, zeta: float, factor: float, name: str) -> tuple[float, float]:
    """omega^2 = factor k / M and 2 zeta omega = factor b / M (factor 4 for translation, 12 for rotation)."""
    if not f > 0:
        raise SceneError(f"frame.{name}_frequency: {f:g} Hz is outside the allowed range (0, inf)")
    if not 0 <= zeta < 1:
        raise SceneError(f"frame.{name}_damping_ratio: {zeta:g} is outside the allowed range [0, 1)")
    w = 2 * np.pi * f
    return mass * w * w / factor, 2 * zeta * w * mass / factor


def corner_jacobians(params: FrameParameters) -> NDArray[np.float64]:
    """J_j (4, 3, 6): small displacement of corner j per generalized coordinate (translation + r x c_j)."""
    return _corner_jacobians(float(params.lx), float(params.ly)).copy()


@lru_cache(maxsize=64)
def _corner_jacobians(lx: float, ly: float) -> NDArray[np.float64]:
    jac = np.zeros((4, 3, 6))
    for j, (sx, sy) in enumerate(CORNER_SIGNS):
        jac[j, :, :3] = np.eye(3)
        jac[j, :, 3:] = -_skew(np.array([sx * lx / 2, sy * ly / 2, 0.0]))  # r x c = -c x r
    return jac


def _skew(v: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


@dataclass(frozen=True)
class LinearFrame:
    """Linearized model x' = A x + B_spring a + B_damper a', y = C x, with named states and inputs.

    States: (x, y, z, rx, ry, rz, and their rates); inputs: base displacement of corner j along
    axis X/Y/Z ("c0.x", ...); outputs: the roof's slopes (h_x, h_y) = (-ry, rx).
    """

    a: NDArray[np.float64]
    b_spring: NDArray[np.float64]
    b_damper: NDArray[np.float64]
    c: NDArray[np.float64]
    stiffness: NDArray[np.float64]  # diagonal generalized stiffness K_q
    damping: NDArray[np.float64]  # diagonal generalized damping C_q
    mass: NDArray[np.float64]  # generalized mass
    force_spring: NDArray[np.float64]  # (6, 12) generalized force per unit base displacement
    force_damper: NDArray[np.float64]
    state_names: tuple[str, ...] = tuple(COORDINATES) + tuple(f"d{c}" for c in COORDINATES)
    input_names: tuple[str, ...] = tuple(f"c{j}.{ax}" for j in range(4) for ax in "xyz")
    output_names: tuple[str, ...] = ("slope_x", "slope_y")
    names: dict = field(default_factory=lambda: dict(MODE_OF_COORDINATE))

    @property
    def frequencies_hz(self) -> NDArray[np.float64]:
        """Undamped natural frequency of each generalized coordinate."""
        return np.sqrt(self.stiffness / self.mass) / (2 * np.pi)

    @property
    def damping_ratios(self) -> NDArray[np.float64]:
        return self.damping / (2 * np.sqrt(self.stiffness * self.mass))

    def eigen_modes(self) -> dict[str, tuple[float, float]]:
        """{coordinate: (|lambda| / 2 pi, -Re lambda / |lambda|)} from the eigenvalues of A."""
        out = {}
        for i, name in enumerate(COORDINATES):
            sub = self.a[np.ix_([i, i + 6], [i, i + 6])]
            li = np.linalg.eigvals(sub)[0]
            out[name] = (abs(li) / (2 * np.pi), -li.real / abs(li))
        return out

    def discretize(self, dt: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Exact zero-order-hold discretization (Phi, Gamma) of x' = A x + B_spring a at step dt."""
        n, m = self.a.shape[0], self.b_spring.shape[1]
        aug = np.zeros((n + m, n + m))
        aug[:n, :n], aug[:n, n:] = self.a * dt, self.b_spring * dt
        e = expm(aug)
        return e[:n, :n], e[:n, n:]


def linearize(params: FrameParameters) -> LinearFrame:
    """The linear state-space model about the flat equilibrium (12 states, 12 base inputs)."""
    jac = corner_jacobians(params)
    kq = np.einsum("jai,a,jak->ik", jac, params.stiffness, jac)
    cq = np.einsum("jai,a,jak->ik", jac, params.damping, jac)
    if np.abs(kq - np.diag(np.diag(kq))).max() > 1e-9 * np.abs(kq).max():
        raise AssertionError("frame: generalized coordinates do not decouple")  # pragma: no cover
    m = params.generalized_mass
    fk = np.concatenate([jac[j].T * params.stiffness for j in range(4)], axis=1)  # (6, 12)
    fb = np.concatenate([jac[j].T * params.damping for j in range(4)], axis=1)
    a = np.zeros((12, 12))
    a[:6, 6:] = np.eye(6)
    a[6:, :6] = -kq / m[:, None]
    a[6:, 6:] = -cq / m[:, None]
    b_spring = np.vstack([np.zeros((6, 12)), fk / m[:, None]])
    b_damper = np.vstack([np.zeros((6, 12)), fb / m[:, None]])
    c = np.zeros((2, 12))
    c[0, 4], c[1, 3] = -1.0, 1.0
    return LinearFrame(a, b_spring, b_damper, c, np.diag(kq).copy(), np.diag(cq).copy(), m, fk, fb)


@dataclass(frozen=True)
class Drive:
    """Circular base displacement of one corner, eq. (11): sum_i A_i (cos(w_i t) d1 + sin(w_i t) d2)."""

    frequencies: NDArray[np.float64]  # Hz
    amplitudes: NDArray[np.float64]  # m
    corner: int = 0
    d1: NDArray[np.float64] = field(default_factory=lambda: np.array([1.0, 0.0, 0.0]))
    d2: NDArray[np.float64] = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    phases: NDArray[np.float64] | None = None  # rad; A_i (cos(w_i t + phase_i) d1 + sin(w_i t + phase_i) d2)

    def phasors(self) -> NDArray[np.complex128]:
        """Complex base-displacement amplitudes (n_freq, 12): a(t) = Re(phasor e^{i w t})."""
        out = np.zeros((self.frequencies.size, 12), dtype=complex)
        amp = self.amplitudes * (np.exp(1j * self.phases) if self.phases is not None else 1.0)
        out[:, 3 * self.corner : 3 * self.corner + 3] = amp[:, None] * (self.d1 - 1j * self.d2)[None, :]
        return out

    def base(self, t: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Base displacement and velocity (12,) at time t."""
        w = 2 * np.pi * self.frequencies
        ph = self.phasors()
        e = np.exp(1j * w * t)
        return (ph * e[:, None]).real.sum(0), (ph * (1j * w * e)[:, None]).real.sum(0)


def steady_state(
    lin: LinearFrame, drive: Drive, t: NDArray[np.float64], coords=slice(None)
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Exact steady-state (q, q') of the linear model under the drive: shape (T, 6) each (or the
    selected `coords`), O(T n_freq)."""
    n = len(range(6)[coords])
    q = np.zeros((t.size, n))
    dq = np.zeros((t.size, n))
    for w, ph in zip(2 * np.pi * drive.frequencies, drive.phasors()):
        force = (lin.force_spring + 1j * w * lin.force_damper) @ ph
        qh = (force / (lin.stiffness - w * w * lin.mass + 1j * w * lin.damping))[coords]
        e = np.exp(1j * w * t)[:, None]
        q += (qh[None, :] * e).real
        dq += (1j * w * qh[None, :] * e).real
    return q, dq


def mode_zoh(k: float, c: float, m: float, dt: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Exact ZOH (Phi, Gamma) of m q'' + c q' + k q = g for one coordinate (2 states).

    Underdamped (zeta <= 0.9, k > 0): the closed form of the matrix exponential of
    A = [[0, 1], [-w^2, -2 zeta w]] with Gamma = A^-1 (Phi - I) B, B = (0, 1/m) (the likelihood's
    hot path; equal to the matrix exponential to 2e-13 at w dt >= 6e-4, and to 3e-11 at w dt = 6e-6
    where Phi - I cancels; tested). Otherwise the matrix exponential itself, which stays exact
    through critical and over-damping."""
    if k > 0 and m > 0:
        w = math.sqrt(k / m)
        zeta = c / (2 * m * w)
        if 0 <= zeta <= 0.9:
            s = math.sqrt(1 - zeta * zeta)
            wd = w * s
            e = math.exp(-zeta * w * dt)
            cs, sn = math.cos(wd * dt), math.sin(wd * dt)
            phi = np.array([[e * (cs + zeta / s * sn), e * sn / wd], [-e * w * w * sn / wd, e * (cs - zeta / s * sn)]])
            a_inv = np.array([[-2 * zeta / w, -1 / (w * w)], [1.0, 0.0]])
            return phi, a_inv @ ((phi - np.eye(2)) @ np.array([0.0, 1.0 / m]))
    aug = np.zeros((3, 3))
    aug[0, 1] = dt
    aug[1, 0], aug[1, 1], aug[1, 2] = -k / m * dt, -c / m * dt, dt / m
    e = expm(aug)
    return e[:2, :2], e[:2, 2]


def propagate_zoh(
    phi: NDArray[np.float64], gam: NDArray[np.float64], g: NDArray[np.float64], x0: NDArray[np.float64]
) -> NDArray[np.float64]:
    """x_k for x_{k+1} = Phi x_k + Gamma g_k, x_0 = x0, as second-order IIR filters (O(T), in C).

    Cayley-Hamilton: both the forced and the free response obey the recursion with denominator
    1 - tr(Phi) z^-1 + det(Phi) z^-2; numerators follow from adj(zI - Phi) = zI + Phi - tr(Phi) I.
    """
    from scipy.signal import lfilter  # here, not at import: scipy.signal costs ~1 s of every CLI start

    tr, det = np.trace(phi), np.linalg.det(phi)
    den = np.array([1.0, -tr, det])
    n = g.size
    forced = np.stack([lfilter([0.0, gam[i], ((phi - tr * np.eye(2)) @ gam)[i]], den, g) for i in range(2)], axis=1)
    # free response Phi^k x0 = s_k Phi x0 - det s_{k-1} x0, s_0 = 0, s_1 = 1, s_{k+1} = tr s_k - det s_{k-1}
    impulse = np.zeros(n + 1)
    impulse[1] = 1.0
    s = lfilter([1.0], den, impulse)  # s[k] = s_k
    free = np.empty((n, 2))
    free[0] = x0
    free[1:] = np.outer(s[1:n], phi @ x0) - det * np.outer(s[: n - 1], x0)  # row k: Phi^k x0
    return forced + free


def simulate_linear(
    params: FrameParameters,
    drive: Drive | None,
    noise_rms: float,
    fs: float,
    n: int,
    rng: np.random.Generator,
    start: float = 0.0,
    base_noise: NDArray[np.float64] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Generalized coordinates (q, q') (n, 6) at t = start + k/fs: exact steady-state drive response
    plus the exact ZOH response to white base noise, started from its stationary distribution.

    `base_noise` (n, 12) replaces the random draw (to share one realization with the nonlinear model).
    """
    lin = linearize(params)
    t = start + np.arange(n) / fs
    if drive is not None and drive.frequencies.size:
        q, dq = steady_state(lin, drive, t)
    else:
        q, dq = np.zeros((n, 6)), np.zeros((n, 6))
    if noise_rms > 0 or base_noise is not None:
        a = rng.normal(0.0, noise_rms, (n, 12)) if base_noise is None else base_noise
        g = a @ lin.force_spring.T  # generalized force per sample (n, 6)
        var = noise_rms**2 * np.einsum("ij,ij->i", lin.force_spring, lin.force_spring)
        for i in range(6):
            phi, gam = mode_zoh(lin.stiffness[i], lin.damping[i], lin.mass[i], 1.0 / fs)
            x0 = np.zeros(2)
            if lin.damping[i] > 0 and base_noise is None:
                p = solve_discrete_lyapunov(phi, var[i] * np.outer(gam, gam))
                x0 = rng.multivariate_normal(np.zeros(2), (p + p.T) / 2, method="eigh")
            x = propagate_zoh(phi, gam, g[:, i], x0)
            q[:, i] += x[:, 0]
            dq[:, i] += x[:, 1]
    return q, dq


# ---------------------------------------------------------------- nonlinear 6-DOF, quaternion attitude


def quat_to_matrix(qt: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotation matrix (body -> world) of a quaternion (w, x, y, z), normalized first."""
    w, x, y, z = qt / np.linalg.norm(qt)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def quat_from_rotation_vector(r: NDArray[np.float64]) -> NDArray[np.float64]:
    ang = np.linalg.norm(r)
    if ang < 1e-300:
        return np.array([1.0, 0.0, 0.0, 0.0])
    return np.concatenate([[np.cos(ang / 2)], np.sin(ang / 2) * r / ang])


class NonlinearFrame:
    """Rigid-body dynamics (14)-(15) with a quaternion attitude. State (13,): r_cm, v_cm, quaternion,
    body rates omega."""

    def __init__(self, params: FrameParameters):
        self.p = params
        self.corners = params.corners()
        self.inertia = params.inertia
        self.k = params.stiffness
        self.b = params.damping

    def rhs(
        self, t: float, s: NDArray[np.float64], base: NDArray[np.float64], base_rate: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """Time derivative; base (12,) and base_rate (12,) are the spring bases' displacement and velocity."""
        r, v, qt, om = s[:3], s[3:6], s[6:10], s[10:13]
        rot = quat_to_matrix(qt)
        arm = self.corners @ rot.T  # (4, 3) world-frame lever arms
        vel = v + _cross(rot @ om, arm)
        disp = r + arm - self.corners - base.reshape(4, 3)
        force = -self.k * disp - self.b * (vel - base_rate.reshape(4, 3))
        torque_body = rot.T @ _cross(arm, force).sum(0)
        dom = (torque_body - _cross(om, self.inertia * om)) / self.inertia
        w, x, y, z = qt
        ox, oy, oz = om
        dq = 0.5 * np.array(
            [-x * ox - y * oy - z * oz, w * ox + y * oz - z * oy, w * oy + z * ox - x * oz, w * oz + x * oy - y * ox]
        )
        return np.concatenate([v, force.sum(0) / self.p.mass, dq, dom])

    def energy(self, s: NDArray[np.float64]) -> float:
        """Kinetic + spring energy (no base motion)."""
        r, v, qt, om = s[:3], s[3:6], s[6:10], s[10:13]
        arm = self.corners @ quat_to_matrix(qt).T
        disp = r + arm - self.corners
        return 0.5 * self.p.mass * v @ v + 0.5 * om @ (self.inertia * om) + 0.5 * np.sum(self.k * disp**2)

    def simulate(
        self,
        t: NDArray[np.float64],
        s0: NDArray[np.float64],
        drive: Drive | None = None,
        base_noise: NDArray[np.float64] | None = None,
        rtol: float = 1e-10,
        atol: float = 1e-14,
    ) -> NDArray[np.float64]:
        """States at times t (uniform). Base noise (len(t), 12) is held constant over each sample."""
        from scipy.integrate import solve_ivp  # here, not at import: scipy.integrate costs ~1 s

        def base(tt: float, k: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
            a, da = drive.base(tt) if drive is not None else (np.zeros(12), np.zeros(12))
            if base_noise is not None:
                a = a + base_noise[k]
            return a, da

        out = np.empty((t.size, 13))
        out[0] = s0
        if base_noise is None:
            sol = solve_ivp(
                lambda tt, s: self.rhs(tt, s, *base(tt, 0)),
                (t[0], t[-1]),
                s0,
                method="DOP853",
                t_eval=t,
                rtol=rtol,
                atol=atol,
            )
            return sol.y.T
        s = np.asarray(s0, dtype=float)
        for k in range(t.size - 1):
            sol = solve_ivp(
                lambda tt, y: self.rhs(tt, y, *base(tt, k)), (t[k], t[k + 1]), s, method="DOP853", rtol=rtol, atol=atol
            )
            s = sol.y[:, -1]
            out[k + 1] = s
        return out

    def state_from_linear(self, q: NDArray[np.float64], dq: NDArray[np.float64]) -> NDArray[np.float64]:
        """Nonlinear state matching generalized coordinates (small rotation vector and its rate)."""
        qt = quat_from_rotation_vector(q[3:])
        om_body = quat_to_matrix(qt).T @ dq[3:]
        return np.concatenate([q[:3], dq[:3], qt, om_body])


def _cross(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """a x b over the last axis (np.cross costs ~17 us a call, and the ODE right-hand side makes three)."""
    a, b = np.broadcast_arrays(a, b)
    out = np.empty(a.shape)
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def slopes_of_attitude(states: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Roof slopes (h_x, h_y) = (-n_x/n_z, -n_y/n_z) of the body normal e3 for nonlinear states (T, 13)."""
    qt = states[:, 6:10] / np.linalg.norm(states[:, 6:10], axis=1, keepdims=True)
    w, x, y, z = qt.T
    n = np.stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)], axis=1)
    return -n[:, 0] / n[:, 2], -n[:, 1] / n[:, 2]


# ---------------------------------------------------------------- the scene's motion


class TiltSeries(ModalMotion):
    """A rigid roof's realized slopes on a time grid, the same at every point of the roof: a modal
    motion whose two coordinates are the slopes (h_x, h_y) and whose shapes are uniform."""

    def __init__(self, t: NDArray[np.float64], hx: NDArray[np.float64], hy: NDArray[np.float64]):
        self.t, self.hx, self.hy = t, hx, hy

    def shapes(self, x, y):
        n = np.asarray(x).size
        out = np.zeros((2, 2, n))
        out[0, 0], out[1, 1] = 1.0, 1.0
        return out

    def coefficients(self, t):
        t = np.asarray(t, dtype=float)
        return np.stack([np.interp(t, self.t, self.hx), np.interp(t, self.t, self.hy)], axis=1)


class FrameMotion(Motion):
    """The roof on its resonant frame; realized per simulation (the noise is random)."""

    line_keys = ("drive_frequency", "drive_amplitude", "drive_phase")

    def __init__(self, params: FrameParameters, drive: Drive | None, noise_rms: float = 0.0, model: str = "linear"):
        self.params, self.drive, self.noise_rms, self.model = params, drive, float(noise_rms), model

    def max_frequency(self) -> float:
        return float(self.drive.frequencies.max()) if self.drive is not None and self.drive.frequencies.size else 0.0

    def prepare(self, t: NDArray[np.float64], rng: np.random.Generator) -> Motion:
        t = np.asarray(t, dtype=float)
        if t.size < 2 or not np.allclose(np.diff(t), t[1] - t[0], rtol=1e-9, atol=0):
            raise SceneError("frame motion: needs uniformly sampled times (exact discretization)")
        fs = 1.0 / (t[1] - t[0])
        if self.model == "linear":
            q, _ = simulate_linear(self.params, self.drive, self.noise_rms, fs, t.size, rng, start=t[0])
            return TiltSeries(t, -q[:, 4], q[:, 3])
        noise = rng.normal(0.0, self.noise_rms, (t.size, 12)) if self.noise_rms > 0 else None
        q0, dq0 = simulate_linear(self.params, self.drive, 0.0, fs, 1, rng, start=t[0])
        nl = NonlinearFrame(self.params)
        states = nl.simulate(t, nl.state_from_linear(q0[0], dq0[0]), self.drive, noise)
        return TiltSeries(t, *slopes_of_attitude(states))

    def slopes(self, x, y, t):
        raise SceneError("frame motion: call prepare(t, rng) first (the scene does this)")

    @classmethod
    def from_table(cls, t: Table, x_range: tuple[float, float], y_range: tuple[float, float]) -> FrameMotion:
        """Scene table: mass; either k_vertical, b_vertical, k_lateral, b_lateral (physical) or
        {vertical|tilt}_frequency + _damping_ratio and {lateral|twist}_frequency + _damping_ratio
        (modal); drive_frequency, drive_amplitude, drive_phase (lists), drive_corner, drive_plane;
        noise_rms; model."""
        lx, ly = x_range[1] - x_range[0], y_range[1] - y_range[0]
        mass = t.number("mass", 1.0, lo=0.0, lo_open=True)
        physical = ("k_vertical", "b_vertical", "k_lateral", "b_lateral")
        if any(t.has(k) for k in physical):
            params = FrameParameters(
                mass,
                lx,
                ly,
                t.number("k_vertical", lo=0.0, lo_open=True),
                t.number("b_vertical", lo=0.0),
                t.number("k_lateral", lo=0.0, lo_open=True),
                t.number("b_lateral", lo=0.0),
            )
        else:
            modes = {
                m: (
                    t.number(f"{m}_frequency", lo=0.0, lo_open=True),
                    t.number(f"{m}_damping_ratio", lo=0.0, hi=1.0, hi_open=True),
                )
                for m in ("vertical", "tilt", "lateral", "twist")
                if t.has(f"{m}_frequency")
            }
            params = FrameParameters.from_modal(lx, ly, mass, **modes)
        freqs = np.array(t.numbers("drive_frequency", [], lo=0.0, lo_open=True))
        amps = np.array(t.numbers("drive_amplitude", [], lo=0.0))
        phases = np.array(t.numbers("drive_phase", [0.0] * freqs.size))
        if freqs.size != amps.size or freqs.size != phases.size:
            raise SceneError(
                f"{t.path('drive_amplitude')}: needs one amplitude per drive_frequency ({freqs.size}), "
                f"got {amps.size} amplitudes and {phases.size} phases"
            )
        corner = t.integer("drive_corner", 0, 0, 3)
        plane = t.raw("drive_plane", [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
        d1, d2 = _plane(plane, t.path("drive_plane"))
        drive = Drive(freqs, amps, corner, d1, d2, phases) if freqs.size else None
        model = t.choice("model", "linear", ("linear", "nonlinear"))
        return cls(params, drive, t.number("noise_rms", 0.0, lo=0.0), model)


def _plane(plane: object, key: str) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    try:
        d = np.array(plane, dtype=float)
    except (TypeError, ValueError):
        raise SceneError(f"{key}: must be two 3-vectors [[x, y, z], [x, y, z]]") from None
    if d.shape != (2, 3) or not np.all(np.isfinite(d)):
        raise SceneError(f"{key}: must be two 3-vectors [[x, y, z], [x, y, z]]")
    n1, n2 = np.linalg.norm(d, axis=1)
    if n1 == 0 or n2 == 0 or abs(d[0] @ d[1]) > 1e-9 * n1 * n2:
        raise SceneError(f"{key}: the two directions must be non-zero and perpendicular")
    return d[0] / n1, d[1] / n2

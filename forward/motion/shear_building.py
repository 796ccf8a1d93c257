"""Shear buildings under ambient forcing: the simulated truth of operational modal analysis (OMA).

A shear building of n storeys is a chain of lumped floor masses m_1..m_n (kg) joined by storey
stiffnesses k_1..k_n (N/m; storey i joins floor i - 1 and floor i, floor 0 the rigid ground). Its
lateral floor displacements u (m) obey

    M u'' + C u' + K u = f(t),    M = diag(m),    K tridiagonal: K_ii = k_i + k_{i+1}, K_{i,i+1} = -k_{i+1},

with f the floor forces (N). The damping is classical (modal): C = M Phi diag(2 zeta_k omega_k)
Phi^T M, so the modes are real and each modal coordinate q_k (u = Phi q) obeys its own equation

    q_k'' + 2 zeta_k omega_k q_k' + omega_k^2 q_k = phi_k^T f(t),

where K phi = omega^2 M phi (scipy.linalg.eigh) and the shapes are mass-normalized, Phi^T M Phi = I.

Forcing: independent floor forces held constant over each sample interval (zero-order hold, ZOH),
their levels white (independent from sample to sample) or coloured (an AR(1) sequence, the
sampled Ornstein-Uhlenbeck process with a corner frequency). Under a held force each mode's
discretization is exact: x_{n+1} = Phi_k x_n + Gamma_k p_n with x = (q, q'), (Phi_k, Gamma_k)
from the matrix exponential of the augmented system, so the samples are the continuous-time
response at the sample instants without any integration error. The acceleration is exact too:
q'' = -omega^2 q - 2 zeta omega q' + p_n (the force acting over [t_n, t_{n+1})). Every record
starts in the stationary state (drawn from the stationary covariance of the joint modal and
forcing state), so there is no start-up transient.

`TwoWayShearBuilding` puts two uncoupled shear buildings on the two lateral directions x, y of one
plan (no torsion); a sensor at a storey measuring at an angle in plan sees cos(angle) x + sin(angle) y,
so two directions of nearly equal frequency share the channels.

SI units throughout; frequencies in Hz.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import eigh, expm, solve_discrete_lyapunov
from scipy.signal import lfilter

from forward.errors import SceneError

QUANTITIES = ("acceleration", "velocity", "displacement")
FORCINGS = ("white", "coloured")
_CHUNK = 1 << 17  # samples simulated at a time: memory stays ~ chunk x (floors + channels) whatever the record

Channel = int | tuple[int, float]  # a storey (1..n, along x) or (storey, angle in plan in degrees from x)


@dataclass(frozen=True)
class Modes:
    """Real modes of a classically damped structure: undamped natural frequencies (Hz, ascending),
    damping ratios, mass-normalized shapes (dof, mode) with shapes^T M shapes = I, the lumped masses
    (kg) of the degrees of freedom, and their names."""

    frequencies: NDArray[np.float64]
    damping_ratios: NDArray[np.float64]
    shapes: NDArray[np.float64]
    masses: NDArray[np.float64]
    dofs: tuple[str, ...]

    @property
    def omegas(self) -> NDArray[np.float64]:
        """Circular natural frequencies omega = 2 pi f (rad/s)."""
        return 2.0 * np.pi * self.frequencies


def _per_storey(value: ArrayLike, n: int, name: str) -> NDArray[np.float64]:
    arr = (
        np.broadcast_to(np.asarray(value, dtype=float), (n,)).copy()
        if np.ndim(value) == 0
        else np.asarray(value, float)
    )
    if arr.shape != (n,):
        raise SceneError(f"shear_building.{name}: need one value or {n} (one per storey); got {arr.size}")
    if not np.all(np.isfinite(arr)) or not np.all(arr > 0):
        raise SceneError(f"shear_building.{name}: every value must be in (0, inf)")
    return arr


def rayleigh_damping_ratios(
    frequencies: ArrayLike, first: tuple[float, float], second: tuple[float, float]
) -> NDArray[np.float64]:
    """Damping ratios of Rayleigh damping C = a M + b K through two (frequency Hz, ratio) anchors:
    zeta(omega) = a / (2 omega) + b omega / 2, with a, b solved from the anchors."""
    (f1, z1), (f2, z2) = first, second
    w1, w2 = 2 * math.pi * f1, 2 * math.pi * f2
    a, b = np.linalg.solve([[1 / (2 * w1), w1 / 2], [1 / (2 * w2), w2 / 2]], [z1, z2])
    w = 2 * np.pi * np.asarray(frequencies, float)
    return a / (2 * w) + b * w / 2


class ShearBuilding:
    """A shear building (module docstring): `storeys` floors, floor `masses` (kg), storey
    `stiffnesses` (N/m; storey i joins floor i - 1 and floor i), `damping_ratios` one for every
    mode or one per mode in ascending frequency (modal damping, so the modes are real; use
    `rayleigh_damping_ratios` for Rayleigh damping)."""

    def __init__(self, storeys: int, masses: ArrayLike, stiffnesses: ArrayLike, damping_ratios: ArrayLike):
        n = int(storeys)
        if n < 1:
            raise SceneError(f"shear_building.storeys: {storeys} is outside the allowed range [1, inf)")
        self.storeys = n
        self.masses = _per_storey(masses, n, "masses")
        self.stiffnesses = _per_storey(stiffnesses, n, "stiffnesses")
        z = np.asarray(damping_ratios, float)
        z = np.full(n, float(z)) if z.ndim == 0 else z
        if z.shape != (n,) or not np.all((z > 0) & (z < 1)):
            raise SceneError(f"shear_building.damping_ratios: need one value or {n}, each in (0, 1)")
        self.damping_ratios = z

    @classmethod
    def with_first_frequency(
        cls,
        storeys: int,
        frequency: float,
        damping_ratios: ArrayLike,
        masses: ArrayLike = 1.0e5,
        stiffness_profile: ArrayLike = 1.0,
    ) -> ShearBuilding:
        """The building whose storey stiffnesses are `stiffness_profile` (relative, one or one per
        storey) scaled so that its first natural frequency is `frequency` (Hz): omega^2 is linear in
        a common stiffness scale, so scale = (omega_target / omega_1(profile))^2."""
        if not frequency > 0:
            raise SceneError(f"shear_building.frequency: {frequency:g} Hz is outside the allowed range (0, inf)")
        trial = cls(storeys, masses, stiffness_profile, damping_ratios)
        scale = (frequency / trial.frequencies[0]) ** 2
        return cls(storeys, trial.masses, trial.stiffnesses * scale, damping_ratios)

    @property
    def mass_matrix(self) -> NDArray[np.float64]:
        """M = diag(m) (kg)."""
        return np.diag(self.masses)

    @property
    def stiffness_matrix(self) -> NDArray[np.float64]:
        """K (N/m): K_ii = k_i + k_{i+1} (k_{n+1} = 0), K_{i,i+1} = K_{i+1,i} = -k_{i+1}."""
        k = self.stiffnesses
        kk = np.diag(k + np.append(k[1:], 0.0))
        kk -= np.diag(k[1:], 1) + np.diag(k[1:], -1)
        return kk

    @property
    def damping_matrix(self) -> NDArray[np.float64]:
        """The classical damping matrix C = M Phi diag(2 zeta omega) Phi^T M (N s/m)."""
        m = self.modal()
        mp = self.mass_matrix @ m.shapes
        return mp @ np.diag(2 * m.damping_ratios * m.omegas) @ mp.T

    def modal(self) -> Modes:
        """The real modes: K phi = omega^2 M phi (scipy.linalg.eigh, ascending; eigh returns
        M-orthonormal vectors, phi^T M phi = 1), each shape's sign with its largest component positive."""
        w2, phi = eigh(self.stiffness_matrix, self.mass_matrix)
        phi = phi * _sign(phi)[None, :]
        return Modes(np.sqrt(w2) / (2 * np.pi), self.damping_ratios.copy(), phi, self.masses.copy(), self.dof_names)

    @property
    def frequencies(self) -> NDArray[np.float64]:
        """Undamped natural frequencies (Hz), ascending."""
        return np.sqrt(eigh(self.stiffness_matrix, self.mass_matrix, eigvals_only=True)) / (2 * np.pi)

    @property
    def dof_names(self) -> tuple[str, ...]:
        return tuple(f"storey{i}" for i in range(1, self.storeys + 1))

    def observation(self, channels: Sequence[Channel]) -> tuple[NDArray[np.float64], tuple[str, ...]]:
        """(the (channels, dofs) matrix that maps floor motion to the sensors, channel names): a storey
        s (1..n) measures its floor; (s, angle) measures cos(angle) of it (the building moves along x only)."""
        rows, names = [], []
        for ch in channels:
            s, angle = _channel(ch, self.storeys)
            row = np.zeros(self.storeys)
            row[s - 1] = math.cos(math.radians(angle))
            rows.append(row)
            names.append(f"storey{s}" if angle == 0 else f"storey{s}@{angle:g}deg")
        return np.array(rows).reshape(len(rows), self.storeys), tuple(names)


class TwoWayShearBuilding:
    """Two uncoupled shear buildings on the plan's x and y directions (same storey count, no
    torsion): dofs (x_1..x_n, y_1..y_n), the modes of both directions sorted by frequency. A
    channel (s, angle) measures cos(angle) x_s + sin(angle) y_s; a bare storey s measures x_s."""

    def __init__(self, x: ShearBuilding, y: ShearBuilding):
        if x.storeys != y.storeys:
            raise SceneError(f"two_way.y: {y.storeys} storeys; the x building has {x.storeys}")
        self.x, self.y, self.storeys = x, y, x.storeys

    @property
    def dof_names(self) -> tuple[str, ...]:
        return tuple(f"storey{i}x" for i in range(1, self.storeys + 1)) + tuple(
            f"storey{i}y" for i in range(1, self.storeys + 1)
        )

    @property
    def frequencies(self) -> NDArray[np.float64]:
        """Both directions' undamped natural frequencies (Hz), ascending."""
        return self.modal().frequencies

    def modal(self) -> Modes:
        """Both directions' modes (each zero in the other direction's dofs), by ascending frequency."""
        n = self.storeys
        mx, my = self.x.modal(), self.y.modal()
        shapes = np.zeros((2 * n, 2 * n))
        shapes[:n, :n], shapes[n:, n:] = mx.shapes, my.shapes
        f = np.concatenate([mx.frequencies, my.frequencies])
        z = np.concatenate([mx.damping_ratios, my.damping_ratios])
        order = np.argsort(f, kind="stable")
        return Modes(f[order], z[order], shapes[:, order], np.concatenate([mx.masses, my.masses]), self.dof_names)

    def observation(self, channels: Sequence[Channel]) -> tuple[NDArray[np.float64], tuple[str, ...]]:
        n = self.storeys
        rows, names = [], []
        for ch in channels:
            s, angle = _channel(ch, n)
            row = np.zeros(2 * n)
            row[s - 1], row[n + s - 1] = math.cos(math.radians(angle)), math.sin(math.radians(angle))
            row[np.abs(row) < 1e-15] = 0.0
            rows.append(row)
            label = {0.0: "x", 90.0: "y"}.get(float(angle) % 360.0, f"@{angle:g}deg")
            names.append(f"storey{s}{label}")
        return np.array(rows).reshape(len(rows), 2 * n), tuple(names)


def _channel(ch: Channel, n: int) -> tuple[int, float]:
    s, angle = (ch, 0.0) if np.ndim(ch) == 0 else (ch[0], float(ch[1]))
    if int(s) != s or not 1 <= int(s) <= n:
        raise SceneError(f"channels: storey {s} is outside the allowed range [1, {n}]")
    return int(s), angle


def _sign(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """Per column: the sign that makes its largest-magnitude entry positive (1 for a zero column)."""
    v = np.atleast_2d(v.T).T
    idx = np.argmax(np.abs(v), axis=0)
    s = np.sign(v[idx, np.arange(v.shape[1])])
    return np.where(s == 0, 1.0, s)


def unit_shapes(shapes: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each column scaled to unit Euclidean norm with its largest-magnitude entry positive (the
    sign convention of every shape the OMA bench compares); a zero column stays zero."""
    s = np.array(shapes, dtype=float, copy=True)
    norm = np.linalg.norm(s, axis=0)
    s = s / np.where(norm > 0, norm, 1.0)
    return s * _sign(s)[None, :]


# ------------------------------------------------------------------ exact discretization


def zoh(frequency: float, damping_ratio: float, dt: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(Phi (2, 2), Gamma (2,)) of q'' + 2 zeta omega q' + omega^2 q = p with p held over each step
    dt: x_{n+1} = Phi x_n + Gamma p_n, x = (q, q'), exact. Van Loan's block form: expm([[A, b], [0, 0]]
    dt) = [[Phi, Gamma], [0, 1]] with A = [[0, 1], [-omega^2, -2 zeta omega]], b = (0, 1)."""
    w = 2 * math.pi * frequency
    aug = np.zeros((3, 3))
    aug[0, 1] = 1.0
    aug[1, 0], aug[1, 1], aug[1, 2] = -w * w, -2 * damping_ratio * w, 1.0
    e = expm(aug * dt)
    return e[:2, :2], e[:2, 2]


def forcing_ar(forcing: str, fs: float, corner: float) -> float:
    """The AR(1) coefficient of the held floor-force levels: 0 for white; for coloured
    rho = exp(-2 pi f_c / fs), the Ornstein-Uhlenbeck process of corner frequency f_c (Hz) sampled at fs
    (its spectrum ~ 1 / (1 + (f / f_c)^2) well below fs)."""
    if forcing not in FORCINGS and forcing != "colored":
        raise SceneError(f"forcing: {forcing!r}; allowed: {', '.join(FORCINGS)}")
    if forcing == "white":
        return 0.0
    if not corner > 0:
        raise SceneError(f"forcing_corner: {corner:g} Hz is outside the allowed range (0, inf)")
    return math.exp(-2 * math.pi * corner / fs)


@dataclass(frozen=True)
class _System:
    """The joint discrete model of one simulation: modal states x (K modes x (q, q')) and floor
    forces f (dofs): z_{n+1} = F z_n + e_n, with the output matrices of the three quantities."""

    modes: Modes
    phis: NDArray[np.float64]  # (K, 2, 2)
    gammas: NDArray[np.float64]  # (K, 2)
    rho: float
    force_sd: NDArray[np.float64]  # (dofs,) stationary sd of each floor force (N)
    transition: NDArray[np.float64]  # F, (2K + dofs) square
    stationary: NDArray[np.float64]  # P = F P F^T + Q

    def output(self, quantity: str) -> NDArray[np.float64]:
        """(K, 2K + dofs): each modal coordinate's `quantity` as a row over the joint state;
        acceleration q_k'' = -omega^2 q_k - 2 zeta omega q_k' + phi_k^T f."""
        k, nd = len(self.modes.frequencies), self.modes.shapes.shape[0]
        h = np.zeros((k, 2 * k + nd))
        w, z = self.modes.omegas, self.modes.damping_ratios
        for i in range(k):
            if quantity == "displacement":
                h[i, 2 * i] = 1.0
            elif quantity == "velocity":
                h[i, 2 * i + 1] = 1.0
            else:
                h[i, 2 * i], h[i, 2 * i + 1] = -(w[i] ** 2), -2 * z[i] * w[i]
                h[i, 2 * k :] = self.modes.shapes[:, i]
        return h


def _system(modes: Modes, fs: float, rho: float, force_rms: ArrayLike) -> _System:
    """The joint model and its stationary covariance (scipy's discrete Lyapunov solver): the force
    block is the AR(1) f_{n+1} = rho f_n + sqrt(1 - rho^2) sd e, the modal block x_{n+1} = Phi x_n +
    Gamma phi^T f_n."""
    k, nd = len(modes.frequencies), modes.shapes.shape[0]
    dt = 1.0 / fs
    pg = [zoh(f, z, dt) for f, z in zip(modes.frequencies, modes.damping_ratios)]
    phis = np.array([p for p, _ in pg]).reshape(k, 2, 2)
    gammas = np.array([g for _, g in pg]).reshape(k, 2)
    sd = np.broadcast_to(np.asarray(force_rms, float), (nd,)).astype(float)
    big = np.zeros((2 * k + nd, 2 * k + nd))
    for i in range(k):
        big[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] = phis[i]
        big[2 * i : 2 * i + 2, 2 * k :] = np.outer(gammas[i], modes.shapes[:, i])
    big[2 * k :, 2 * k :] = rho * np.eye(nd)
    q = np.zeros_like(big)
    q[2 * k :, 2 * k :] = np.diag((1.0 - rho**2) * sd**2)
    p = solve_discrete_lyapunov(big, q)
    return _System(modes, phis, gammas, rho, sd, big, 0.5 * (p + p.T))


def modal_response(
    modes: Modes,
    fs: float,
    forces: NDArray[np.float64],
    x0: NDArray[np.float64],
    quantity: str = "displacement",
    _discrete: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(r (L, K), x_end (K, 2)): every mode's `quantity` at the L samples when the floor forces
    `forces` (L, dofs) are held over each sample interval and the modal states (q, q') start at
    `x0` (K, 2); x_end is the state one step after the last sample (to continue a record).

    Exact ZOH recursion x_{n+1} = Phi x_n + Gamma p_n, p = forces @ shapes, evaluated as IIR filters
    (scipy.signal.lfilter): x_n = sum_{j >= 0} Phi^j u_{n-j} with u_0 = x0, u_n = Gamma p_{n-1},
    i.e. the transfer matrix (I - Phi z^-1)^-1 = adj(I - Phi z^-1) / (1 - tr(Phi) z^-1 + det(Phi) z^-2)."""
    if quantity not in QUANTITIES:
        raise SceneError(f"quantity: {quantity!r}; allowed: {', '.join(QUANTITIES)}")
    forces = np.asarray(forces, float)
    n, k = forces.shape[0], len(modes.frequencies)
    p = forces @ modes.shapes
    out = np.empty((n, k))
    x_end = np.empty((k, 2))
    dt = 1.0 / fs
    for i, (f, z) in enumerate(zip(modes.frequencies, modes.damping_ratios)):
        ph, g = zoh(f, z, dt) if _discrete is None else (_discrete[0][i], _discrete[1][i])
        den = [1.0, -(ph[0, 0] + ph[1, 1]), ph[0, 0] * ph[1, 1] - ph[0, 1] * ph[1, 0]]
        u1 = np.empty(n)
        u2 = np.empty(n)
        u1[0], u2[0] = x0[i]
        u1[1:], u2[1:] = g[0] * p[:-1, i], g[1] * p[:-1, i]
        q = lfilter([1.0, -ph[1, 1]], den, u1) + lfilter([0.0, ph[0, 1]], den, u2)
        v = lfilter([0.0, ph[1, 0]], den, u1) + lfilter([1.0, -ph[0, 0]], den, u2)
        x_end[i] = ph @ np.array([q[-1], v[-1]]) + g * p[-1, i]
        w = 2 * math.pi * f
        out[:, i] = (
            q if quantity == "displacement" else v if quantity == "velocity" else -w * w * q - 2 * z * w * v + p[:, i]
        )
    return out, x_end


def stationary_modal_variance(
    building,
    fs: float,
    quantity: str = "displacement",
    forcing: str = "white",
    forcing_corner: float = 2.0,
    force_rms: ArrayLike = 1.0,
) -> NDArray[np.float64]:
    """The stationary variance of each modal coordinate's `quantity` under the held forcing (the
    discrete Lyapunov solution P of the joint model: h P h^T per mode), the analytic value a long
    simulation's sample variance estimates. (White forcing of sd s held over dt approaches continuous
    white noise of intensity s^2 dt, whose displacement variance is s^2 dt |phi|^2 / (4 zeta omega^3),
    as omega dt -> 0.)"""
    sys_ = _system(building.modal(), fs, forcing_ar(forcing, fs, forcing_corner), force_rms)
    h = sys_.output(quantity)
    return np.einsum("ij,jk,ik->i", h, sys_.stationary, h)


def simulate(
    building: ShearBuilding | TwoWayShearBuilding,
    fs: float,
    duration: float,
    channels: Sequence[Channel],
    quantity: str = "acceleration",
    forcing: str = "white",
    noise_rms: float = 0.0,
    drift: float = 0.0,
    seed: int = 0,
    forcing_corner: float = 2.0,
    force_rms: ArrayLike = 1.0,
) -> tuple[NDArray[np.float64], NDArray[np.float64], dict]:
    """(time (N,), values (N, channels), truth) of `duration` s at `fs` Hz.

    The floors are driven by independent held forces of stationary sd `force_rms` (N), white or
    coloured (AR(1) levels with corner `forcing_corner` Hz); the response (exact, module docstring)
    is measured at `channels` (storeys, or (storey, angle in degrees)) as `quantity`. Then each
    channel gets white Gaussian noise of sd `noise_rms` x its stationary response sd, and a random
    walk (a drift) whose rms over the record, sqrt(mean_n E W_n^2), is `drift` x that sd (steps of
    sd drift x sd x sqrt(2 / (N - 1)), W_0 = 0).

    truth: "frequencies" (Hz, undamped), "damping_ratios", "shapes" (channels, modes: the measured
    components of each mode, unit norm, largest-magnitude component positive), "channels" (names),
    "quantity", "fs", "response_sd" (each channel's stationary sd before noise and drift), "noise_sd",
    "drift_step_sd", "forcing", "forcing_ar"."""
    if quantity not in QUANTITIES:
        raise SceneError(f"quantity: {quantity!r}; allowed: {', '.join(QUANTITIES)}")
    if not fs > 0 or not duration > 0:
        raise SceneError("simulate: fs and duration must be in (0, inf)")
    if noise_rms < 0 or drift < 0:
        raise SceneError("simulate: noise_rms and drift must be in [0, inf)")
    n = round(duration * fs)
    if n < 2:
        raise SceneError(f"simulate: duration x fs = {duration * fs:g} samples; need >= 2")
    rng = np.random.default_rng(seed)
    modes = building.modal()
    obs, names = building.observation(channels)
    rho = forcing_ar(forcing, fs, forcing_corner)
    sys_ = _system(modes, fs, rho, force_rms)
    k, nd = len(modes.frequencies), modes.shapes.shape[0]
    mode_to_channel = (obs @ modes.shapes).T  # (K, C): the channels' share of each modal coordinate
    h_modal = sys_.output(quantity)
    h_channels = mode_to_channel.T @ h_modal  # (C, 2K + dofs); acceleration: includes M^-1 f's feedthrough
    response_sd = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", h_channels, sys_.stationary, h_channels), 0.0))

    # the stationary start, then the held forces chunk by chunk
    w, v = np.linalg.eigh(sys_.stationary)
    z0 = v @ (np.sqrt(np.clip(w, 0.0, None)) * rng.standard_normal(w.size))
    x = z0[: 2 * k].reshape(k, 2)
    f_prev = z0[2 * k :]
    innov = math.sqrt(1.0 - rho**2) * sys_.force_sd
    values = np.empty((n, len(names)))
    for a in range(0, n, _CHUNK):
        b = min(n, a + _CHUNK)
        e = rng.standard_normal((b - a, nd)) * innov
        if a == 0:
            e[0] = f_prev  # the stationary first force
            forces = lfilter([1.0], [1.0, -rho], e, axis=0) if rho else e
        else:
            forces = lfilter([1.0], [1.0, -rho], e, axis=0, zi=(rho * f_prev)[None, :])[0] if rho else e
        r, x = modal_response(modes, fs, forces, x, quantity, (sys_.phis, sys_.gammas))
        values[a:b] = r @ mode_to_channel
        f_prev = forces[-1]
    noise_sd = noise_rms * response_sd
    if noise_rms > 0:
        values += rng.standard_normal(values.shape) * noise_sd
    step_sd = drift * response_sd * math.sqrt(2.0 / max(n - 1, 1))
    if drift > 0:
        walk = rng.standard_normal(values.shape) * step_sd
        walk[0] = 0.0
        values += np.cumsum(walk, axis=0)
    truth = {
        "frequencies": modes.frequencies.copy(),
        "damping_ratios": modes.damping_ratios.copy(),
        "shapes": unit_shapes(mode_to_channel.T),
        "channels": names,
        "quantity": quantity,
        "fs": float(fs),
        "response_sd": response_sd,
        "noise_sd": noise_sd,
        "drift_step_sd": step_sd,
        "forcing": "coloured" if forcing == "colored" else forcing,
        "forcing_ar": rho,
    }
    return np.arange(n) / fs, values, truth

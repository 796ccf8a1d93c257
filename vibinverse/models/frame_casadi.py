"""The frame posterior (sec. 4.2) as a casadi expression, for the casadi MAP
(`vibinverse.estimators.casadi_map`): exact gradients and Hessian.

The objective is the same posterior as `vibinverse.posterior.Posterior` on a `FrameModel` (a test
checks that they agree to 1e-9), written in casadi expressions:
- geometry (generalized tilt stiffness, mass and base-force rows) comes from
  `forward.motion.frame.linearize` with unit springs: every one of them is linear in k1 and b1;
- the modal -> physical map k1 = M w^2 / 12, b1 = M zeta w / 6 of `FrameParameters.from_modal`;
- the drive's steady state H(i w) at the stamps, and the closed-form discretization of a damped
  oscillator under a force held over each frame (`vibinverse.kalman.held_oscillator_fill`,
  underdamped) with its stationary start;
- the Kalman recursion as one casadi Function of 50 steps mapped over the series by `mapaccum`, on the
  two states of the one oscillator the pixel sees (both tilt modes are the same oscillator, so what
  the pixel sees of them is that oscillator under the summed noise intensities: `_tilt_blocks`).

Irregular stamps: the discretization is one casadi Function mapped over the distinct steps, and
each Kalman step takes its step's (Phi, Q) by column (`FrameModel`'s step table and index).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import casadi as ca
import numpy as np

from forward.motion.frame import FrameParameters, linearize
from vibinverse.priors import casadi_log_prior, casadi_value
from vibinverse.scene_keys import get_value

# Kalman steps per mapped call of the casadi recursion (`CasadiFrameObjective._kalman`): blocks of
# 1, 10, 50 and 200 steps took 0.28, 0.11, 0.071 and 0.072 s per exact Hessian on 4000 samples
KALMAN_BLOCK = 50

if TYPE_CHECKING:
    from vibinverse.posterior import Posterior


def _held_step(parts: int) -> ca.Function:
    """(w, a, step) -> (Phi, Q) of x = (q, q'), q'' + 2 a q' + w^2 q = u, u held over each of
    `parts` equal parts h of the step at an independent value of variance 1 / h (unit intensity),
    each as a 4-vector in column order: the closed form of `vibinverse.kalman.held_oscillator_fill`
    (underdamped; the integral of the impulse response as (1 - Phi_11) / w^2, without the small-step
    series, which it needs only below w h ~ 1e-3 to stay within 1e-10), composed over the parts by
    squaring."""
    w, a, step = ca.SX.sym("w"), ca.SX.sym("a"), ca.SX.sym("step")
    h = step / parts
    b = ca.sqrt(w * w - a * a)
    ea = ca.exp(-a * h)
    us, uc = ea * ca.sin(b * h) / b, ea * ca.cos(b * h)
    f = ca.SX(2, 2)
    f[0, 0], f[0, 1], f[1, 0], f[1, 1] = uc + a * us, us, -w * w * us, uc - a * us
    g = ca.vertcat((1 - f[0, 0]) / (w * w), us)
    q = g @ g.T / h
    r, s = ca.SX.eye(2), ca.SX.zeros(2, 2)
    m = parts
    while m:  # (Pa, Qa) then (Pb, Qb) is (Pb Pa, Pb Qa Pb^T + Qb)
        if m & 1:
            r, s = f @ r, f @ s @ f.T + q
        m >>= 1
        if m:
            f, q = f @ f, f @ q @ f.T + q
    return ca.Function("held_step", [w, a, step], [ca.vec(r), ca.vec(s)])


def _stationary(phi, q):
    """The stationary covariance's distinct entries (P11, P12, P22) of P = Phi P Phi^T + Q (4-vectors
    in column order), as `vibinverse.kalman.held_stationary`."""
    f11, f21, f12, f22 = phi[0], phi[1], phi[2], phi[3]
    m = ca.vertcat(
        ca.horzcat(f11 * f11, 2 * f11 * f12, f12 * f12),
        ca.horzcat(f11 * f21, f11 * f22 + f12 * f21, f12 * f22),
        ca.horzcat(f21 * f21, 2 * f21 * f22, f22 * f22),
    )
    return ca.solve(ca.DM.eye(3) - m, ca.vertcat(q[0], q[2], q[3]))


class CasadiFrameObjective:
    """-log posterior of a frame Posterior as a casadi Function of the unconstrained parameters z."""

    def __init__(self, problem: Posterior):
        self.problem = problem
        like = problem.model
        self.like = like
        m = like.base["surfaces"][like.roof]["motion"]
        self.mass = float(m.get("mass", 1.0))
        lx = like.roof_surface.x[1] - like.roof_surface.x[0]
        ly = like.roof_surface.y[1] - like.roof_surface.y[0]
        unit = linearize(FrameParameters(self.mass, lx, ly, 1.0, 1.0, 1.0, 1.0))
        check = linearize(FrameParameters(self.mass, lx, ly, 2.0, 3.0, 5.0, 7.0))
        # tilt rows are linear in (k1, b1) alone; verify rather than assume
        assert np.allclose(check.stiffness[3:5], 2.0 * unit.stiffness[3:5])
        assert np.allclose(check.force_spring[3:5], 2.0 * unit.force_spring[3:5])
        assert np.allclose(check.force_damper[3:5], 3.0 * unit.force_damper[3:5])
        self.unit = unit
        self.n_lines = len(m.get("drive_frequency", []) or [])
        self.corner = int(m.get("drive_corner", 0))
        plane = np.array(m.get("drive_plane", [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]), dtype=float)
        self.d1, self.d2 = plane[0] / np.linalg.norm(plane[0]), plane[1] / np.linalg.norm(plane[1])
        gains = {3: like.jac[1], 4: -like.jac[0]}
        self.seen = [i for i in (3, 4) if abs(gains[i]) > 1e-9 * np.abs(like.jac).max()]
        self.h = np.array([gains[i] if j % 2 == 0 else 0.0 for i in self.seen for j in range(2)])
        self.function = self._build()

    def _value(self, values: dict, name: str):
        key = self.like.key + name
        if key in values:
            return values[key]
        return get_value(self.like.base, key)

    def _build(self) -> ca.Function:
        space = self.problem.space
        z = ca.MX.sym("z", len(space))
        values = {n: casadi_value(p, z[i]) for i, (n, p) in enumerate(zip(space.names, space.priors))}
        log_prior = sum(casadi_log_prior(p, z[i], values[n]) for i, (n, p) in enumerate(zip(space.names, space.priors)))
        k = self.like.key
        f_t, zeta = self._value(values, "tilt_frequency"), self._value(values, "tilt_damping_ratio")
        w = 2 * math.pi * f_t
        k1, b1 = self.mass * w * w / 12.0, self.mass * zeta * w / 6.0  # FrameParameters.from_modal, factor 12
        t = ca.DM(self.like.t)
        q = {3: 0.0, 4: 0.0}
        for line in range(self.n_lines):
            f_d = values.get(f"{k}drive_frequency[{line}]", values.get(k + "drive_frequency") if line == 0 else None)
            amp = values.get(f"{k}drive_amplitude[{line}]", values.get(k + "drive_amplitude") if line == 0 else None)
            ph = values.get(f"{k}drive_phase[{line}]", values.get(k + "drive_phase") if line == 0 else None)
            f_d = f_d if f_d is not None else self.like.line_value({}, "drive_frequency", line)
            amp = amp if amp is not None else self.like.line_value({}, "drive_amplitude", line)
            ph = ph if ph is not None else self.like.line_value({}, "drive_phase", line)
            wd = 2 * math.pi * f_d
            sl = slice(3 * self.corner, 3 * self.corner + 3)
            for i in (3, 4):
                c1, c2 = float(self.unit.force_spring[i, sl] @ self.d1), float(self.unit.force_spring[i, sl] @ self.d2)
                # F = (k1 + i wd b1) A e^{i ph} (c1 - i c2); den = K - wd^2 m + i wd C
                ar, ai = amp * ca.cos(ph), amp * ca.sin(ph)
                pr, pi_ = ar * c1 + ai * c2, ai * c1 - ar * c2
                fr, fi = k1 * pr - wd * b1 * pi_, k1 * pi_ + wd * b1 * pr
                dr = k1 * self.unit.stiffness[i] - wd * wd * self.unit.mass[i]
                di = wd * b1 * self.unit.damping[i]
                den = dr * dr + di * di
                qr, qi = (fr * dr + fi * di) / den, (fi * dr - fr * di) / den
                q[i] = q[i] + qr * ca.cos(wd * t) - qi * ca.sin(wd * t)
        gx, gy = -q[4], q[3]
        jac, hs = self.like.jac, self.like.hess
        mean = (
            self.like.x0
            + jac[0] * gx
            + jac[1] * gy
            + 0.5 * (hs[0, 0] * gx * gx + 2 * hs[0, 1] * gx * gy + hs[1, 1] * gy * gy)
        )
        rms = self._value(values, "noise_rms")
        sigma = (
            values["noise.sigma"]
            if "noise.sigma" in values
            else (get_value(self.like.base, "noise.sigma") if "noise" in self.like.base else 0.0)
        )  # as FrameLikelihood
        phi2, q2, kappa, p0 = self._tilt_blocks(w, zeta, k1, rms)
        # the data enter as a parameter, so that one compiled solver serves many series of one design
        y = ca.MX.sym("y", self.like.t.size)
        mask = ca.MX.sym("mask", self.like.t.size)
        ll = self._kalman(y - mean, mask, phi2, q2, kappa, sigma * sigma, p0)
        return ca.Function("neg_log_post", [z, y, mask], [-(log_prior + ll)])

    def data(self, series=None) -> ca.DM:
        """(y with gaps zeroed, mask) of `series` (default: the problem's) as one parameter vector."""
        y = (series or self.like.series).intensity
        return ca.vertcat(ca.DM(np.nan_to_num(y)), ca.DM(np.isfinite(y).astype(float)))

    def __call__(self, z) -> float:
        """-log posterior at z on the problem's own series."""
        n = self.like.t.size
        d = self.data()
        return float(self.function(z, d[:n], d[n:]))

    def _tilt_blocks(self, w, zeta, k1, rms):
        """Per Kalman step (columns; one column on a uniform grid) the unit-intensity (Phi, Q) of the
        tilt oscillator as 4-vectors, the noise intensity of what the pixel sees of it, and the
        unit-intensity stationary covariance (P11, P12, P22) at the frame step.

        Both tilt modes are one oscillator (w^2 = 12 k1 / M and zeta whatever the roof's extents,
        `FrameParameters.from_modal`), driven by independent white noises of intensities kappa_b, and
        the pixel sees sum_b h_b q_b. That sum is itself that oscillator driven by white noise of
        intensity sum_b h_b^2 kappa_b (its state sum_b h_b x_b has the same Phi, noise covariance
        sum_b h_b^2 kappa_b Q and stationary start), so the filter runs on 2 states instead of 4 with
        the same likelihood (the numpy `FrameModel` keeps the 4; a test checks they agree to 1e-10),
        and each exact Hessian IPOPT needs costs ~20 % less (casadi's evaluation of the recursion's
        derivatives, not the arithmetic of a step, takes most of it)."""
        like = self.like
        a = zeta * w
        if like.per_step:
            # the Kalman step k updates with sample k, then predicts over t[k + 1] - t[k]; the steps
            # of m frames (dropped frames) by one mapped Function for each m
            steps = like.steps
            parts = np.maximum(1, np.floor(steps / like.dt + 0.5)).astype(int)
            blocks = [(np.flatnonzero(parts == m), int(m)) for m in np.unique(parts)]
            mapped = [_held_step(m).map(at.size)(w, a, ca.DM(steps[at]).T) for at, m in blocks]
            back = np.argsort(np.concatenate([at for at, _ in blocks])).tolist()  # the steps' own order
            phi_u = ca.horzcat(*(phi for phi, _ in mapped))[:, back]
            q_u = ca.horzcat(*(q for _, q in mapped))[:, back]
            cols = np.append(like.step_index[1:], steps.size - 1)
            phi2, q2 = phi_u[:, cols.tolist()], q_u[:, cols.tolist()]
            p0 = _stationary(phi_u[:, -1], q_u[:, -1])  # the frame step is the table's last
        else:
            phi2, q2 = _held_step(1)(w, a, like.dt)
            p0 = _stationary(phi2, q2)
        # the base force's white-noise intensity: noise_rms^2 x the nominal step (`FrameModel`)
        spring = sum(
            h * h * float(self.unit.force_spring[i] @ self.unit.force_spring[i]) / self.unit.mass[i] ** 2
            for h, i in zip(self.h[::2], self.seen)
        )
        return phi2, q2, rms * rms * like.dt * k1 * k1 * spring, p0

    def _kalman(self, resid, mask, phi2, q2, kappa, r, p0):
        """The Kalman log-likelihood of the seen oscillator (state (q, q'), observed q + noise of
        variance r, started in its stationary state kappa p0 (P11, P12, P22 at unit intensity));
        step k takes column k of phi2 and q2 (or their one column). P is carried as its three
        distinct entries.

        The recursion runs KALMAN_BLOCK steps at a time: one SX Function of a block, unrolled, mapped
        over the blocks by `mapaccum`. casadi pays a fixed cost per mapped call and per derivative
        direction, so one step per call made the exact Hessian ~11x the gradient; blocks of 50 cut
        the Hessian of the 20 s frame objective 3-4x, to the same value (to rounding). The series is
        padded to whole blocks with gaps (mask 0: no update, no likelihood), which leave the log
        likelihood as it is."""
        n = resid.shape[0]
        per_step = phi2.shape[1] > 1
        size = min(KALMAN_BLOCK, n)
        blocks = -(-n // size)
        pad = blocks * size - n
        if pad:
            resid, mask = ca.vertcat(resid, ca.DM.zeros(pad)), ca.vertcat(mask, ca.DM.zeros(pad))
            if per_step:
                phi2 = ca.horzcat(phi2, ca.repmat(phi2[:, -1], 1, pad))
                q2 = ca.horzcat(q2, ca.repmat(q2[:, -1], 1, pad))
        if per_step:  # block b's columns, stacked: (4 size) x blocks
            phi2, q2 = ca.reshape(phi2, 4 * size, blocks), ca.reshape(q2, 4 * size, blocks)
        run = _kalman_block(size, per_step).mapaccum("kf_all", blocks)
        init = ca.vertcat(0, 0, kappa * p0, 0)
        out = run(init, ca.reshape(resid, size, blocks), ca.reshape(mask, size, blocks), phi2, q2, kappa, r)
        return out[-1, -1]


def _kalman_step() -> ca.Function:
    """One step of the seen oscillator's Kalman filter: (state (x0, x1, P11, P12, P22, log
    likelihood so far), y_k, mask_k, Phi and Q as 4-vectors in column order, noise intensity kappa,
    observation variance r) -> the state after updating with y_k and predicting to the next stamp."""
    x0, x1, pa, pb, pc = (ca.SX.sym(n) for n in ("x0", "x1", "pa", "pb", "pc"))
    yk, mk, acc = ca.SX.sym("y"), ca.SX.sym("m"), ca.SX.sym("acc")
    f, g, kap, rs = ca.SX.sym("phi", 4), ca.SX.sym("q", 4), ca.SX.sym("kappa"), ca.SX.sym("r")
    # update with y_k (h = (1, 0)); a gap (m = 0) leaves the state as it is
    s = pa + rs
    v = yk - x0
    ga, gb = mk * pa / s, mk * pb / s
    u0, u1 = x0 + ga * v, x1 + gb * v
    ua, ub, uc = pa - ga * pa, pb - ga * pb, pc - gb * pb
    ll = -0.5 * mk * (ca.log(s) + math.log(2 * math.pi) + v * v / s)
    # predict: Phi (column order f) and Phi P Phi' + kappa Q
    f00, f10, f01, f11 = f[0], f[1], f[2], f[3]
    n0, n1 = f00 * u0 + f01 * u1, f10 * u0 + f11 * u1
    ta, tb = f00 * ua + f01 * ub, f00 * ub + f01 * uc  # row 0 of Phi P
    tc, td = f10 * ua + f11 * ub, f10 * ub + f11 * uc  # row 1 of Phi P
    na = ta * f00 + tb * f01 + kap * g[0]
    nb = ta * f10 + tb * f11 + kap * g[2]
    nc = tc * f10 + td * f11 + kap * g[3]
    state = ca.vertcat(x0, x1, pa, pb, pc, acc)
    return ca.Function("kf", [state, yk, mk, f, g, kap, rs], [ca.vertcat(n0, n1, na, nb, nc, acc + ll)])


def _kalman_block(size: int, per_step: bool) -> ca.Function:
    """`size` Kalman steps unrolled into one SX Function: (state, y (size), mask (size), Phi, Q,
    kappa, r) -> the state after them; Phi and Q are one 4-vector for all steps, or (per_step) the
    steps' 4-vectors stacked (4 size)."""
    step = _kalman_step()
    state, y, m = ca.SX.sym("state", 6), ca.SX.sym("y", size), ca.SX.sym("m", size)
    width = 4 * size if per_step else 4
    f, g, kap, rs = ca.SX.sym("phi", width), ca.SX.sym("q", width), ca.SX.sym("kappa"), ca.SX.sym("r")
    out = state
    for k in range(size):
        cols = slice(4 * k, 4 * k + 4) if per_step else slice(0, 4)
        out = step(out, y[k], m[k], f[cols], g[cols], kap, rs)
    return ca.Function("kf_block", [state, y, m, f, g, kap, rs], [out])

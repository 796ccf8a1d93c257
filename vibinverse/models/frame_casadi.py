"""The frame posterior (sec. 4.2) as a casadi expression, for the casadi MAP
(`vibinverse.estimators.casadi_map`): exact gradients and Hessian.

The objective is the same posterior as `vibinverse.posterior.Posterior` on a `FrameModel` (a test
checks that they agree to 1e-9), written in casadi expressions:
- geometry (generalized tilt stiffness, mass and base-force rows) comes from
  `forward.motion.frame.linearize` with unit springs: every one of them is linear in k1 and b1;
- the modal -> physical map k1 = M w^2 / 12, b1 = M zeta w / 6 of `FrameParameters.from_modal`;
- the drive's steady state H(i w) and the closed-form zero-order-hold of a damped oscillator;
- the Kalman recursion as one casadi step Function unrolled over the series by `mapaccum`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import casadi as ca
import numpy as np

from forward.motion.frame import FrameParameters, linearize
from vibinverse.models.frame import stationary_2x2_entries
from vibinverse.priors import casadi_log_prior, casadi_value
from vibinverse.scene_keys import get_value

if TYPE_CHECKING:
    from vibinverse.posterior import Posterior


def _stationary_2x2(phi, q):
    """P = Phi P Phi^T + Q for 2 x 2 blocks, as a casadi expression (`stationary_2x2_entries`)."""
    p11, p12, p22 = stationary_2x2_entries(phi, q)
    return ca.vertcat(ca.horzcat(p11, p12), ca.horzcat(p12, p22))


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
        phi, qm, p0 = self._tilt_blocks(w, zeta, k1, rms)
        # the data enter as a parameter, so that one compiled solver serves many series of one design
        y = ca.MX.sym("y", self.like.t.size)
        mask = ca.MX.sym("mask", self.like.t.size)
        ll = self._kalman(y - mean, mask, phi, qm, sigma * sigma, p0)
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
        """Closed-form ZOH (Phi, Q) and stationary P of each seen tilt mode (block diagonal)."""
        dt = self.like.dt
        n = 2 * len(self.seen)
        phi, qm, p0 = ca.MX.zeros(n, n), ca.MX.zeros(n, n), ca.MX.zeros(n, n)
        s = ca.sqrt(1 - zeta * zeta)
        wd = w * s
        e = ca.exp(-zeta * w * dt)
        c, sn = ca.cos(wd * dt), ca.sin(wd * dt)
        blk = ca.vertcat(
            ca.horzcat(e * (c + zeta / s * sn), e * sn / wd), ca.horzcat(-e * w * w * sn / wd, e * (c - zeta / s * sn))
        )
        for b, i in enumerate(self.seen):
            m = self.unit.mass[i]
            # Gamma = A^-1 (Phi - I) B, A = [[0, 1], [-w^2, -2 zeta w]], B = [0, 1/m]
            a_inv = ca.vertcat(ca.horzcat(-2 * zeta / w, -1 / (w * w)), ca.horzcat(1, 0))
            gam = ca.mtimes(a_inv, ca.mtimes(blk - ca.DM.eye(2), ca.DM([0.0, 1.0 / m])))
            var = rms * rms * k1 * k1 * float(self.unit.force_spring[i] @ self.unit.force_spring[i])
            qb = var * ca.mtimes(gam, gam.T)
            pb = _stationary_2x2(blk, qb)
            sl = slice(2 * b, 2 * b + 2)
            phi[sl, sl], qm[sl, sl], p0[sl, sl] = blk, qb, 0.5 * (pb + pb.T)
        return phi, qm, p0

    def _kalman(self, resid, mask, phi, qm, r, p0):
        n = phi.shape[0]
        x = ca.SX.sym("x", n)
        p = ca.SX.sym("p", n, n)
        yk, mk = ca.SX.sym("y"), ca.SX.sym("m")
        ph, qs, rs = ca.SX.sym("phi", n, n), ca.SX.sym("q", n, n), ca.SX.sym("r")
        h = ca.DM(self.h)
        s = ca.mtimes([h.T, p, h]) + rs
        v = yk - ca.mtimes(h.T, x)
        gain = ca.mtimes(p, h) / s
        xu = x + mk * gain * v
        pu = p - mk * ca.mtimes(gain, ca.mtimes(h.T, p))
        ll = -0.5 * mk * (ca.log(s) + math.log(2 * math.pi) + v * v / s)
        acc = ca.SX.sym("acc")
        xn = ca.mtimes(ph, xu)
        pn = ca.mtimes([ph, pu, ph.T]) + qs
        step = ca.Function(
            "kf",
            [ca.vertcat(x, ca.reshape(p, n * n, 1), acc), yk, mk, ph, qs, rs],
            [ca.vertcat(xn, ca.reshape(pn, n * n, 1), acc + ll)],
        )
        run = step.mapaccum("kf_all", resid.shape[0])
        init = ca.vertcat(ca.MX.zeros(n), ca.reshape(p0, n * n, 1), 0)
        out = run(init, resid.T, mask.T, phi, qm, r)
        return out[-1, -1]

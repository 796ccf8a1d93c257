"""A new term in a few lines, without touching the engine: a stochastic cycle (Harvey's trigonometric
cycle), e.g. a lamp's 100 Hz flicker whose amplitude and phase wander with correlation time tau.

    x_k = e^{-dt/tau} R(w dt) x_{k-1} + w_k,   Q = var (1 - e^{-2 dt/tau}) I,   seen: x_1

Its autocovariance is var e^{-|t|/tau} cos(w t). Add it to any model with `+`, e.g.
`StochasticCycle() + AR1() + White()`, and `TermSum.log_likelihood` runs it through the one Kalman
engine (`vibinverse.engines.kalman`); run this file to fit one to a simulated flicker.
"""

import math

import numpy as np

from vibinverse.priors import Prior
from vibinverse.terms import Term, register_term


@register_term
class StochasticCycle(Term):
    kind, label = "cycle", "stochastic cycle"

    def names(self):
        return ["cycle.frequency", "cycle.rms", "cycle.time"]

    def blocks(self, facts):
        return [2]

    def fill(self, values, steps, phis, qs, p0, offset, facts):
        f, rms, tau = (values[n] for n in self.names())
        o, decay, turn = offset, np.exp(-steps / tau), 2 * math.pi * f * steps
        phis[:, o, o] = phis[:, o + 1, o + 1] = decay * np.cos(turn)
        phis[:, o, o + 1], phis[:, o + 1, o] = decay * np.sin(turn), -decay * np.sin(turn)
        qs[:, o, o] = qs[:, o + 1, o + 1] = rms**2 * -np.expm1(-2 * steps / tau)
        p0[o, o] = p0[o + 1, o + 1] = rms**2

    def psd(self, values, f, facts):
        f0, rms, tau = (values[n] for n in self.names())
        lorentz = lambda d: 2 * rms**2 * tau / (1 + (2 * math.pi * d * tau) ** 2)
        return lorentz(np.asarray(f) - f0) + lorentz(np.asarray(f) + f0)

    def priors(self, facts):
        return {
            "cycle.frequency": Prior("uniform", (0.0, facts.nyquist)),
            "cycle.rms": Prior("loguniform", (1e-6 * facts.sd, 10 * facts.sd)),
            "cycle.time": Prior("loguniform", (facts.dt, facts.span)),
        }


if __name__ == "__main__":
    from scipy.optimize import minimize

    import vibinverse as vi
    from vibinverse.terms import White

    rng = np.random.default_rng(0)
    t = np.arange(2000) / 1000.0  # 2 s at 1 kHz
    amplitude = 1 + 0.1 * np.cumsum(rng.normal(size=t.size)) / math.sqrt(t.size)  # a wandering amplitude
    y = amplitude * np.cos(2 * math.pi * 100.0 * t) + 0.3 * rng.normal(size=t.size)
    series = vi.series(t, y)
    model = StochasticCycle() + White()
    names = model.names()

    def negative(p):
        return -model.log_likelihood(dict(zip(names, [p[0], *np.exp(p[1:])])), series)

    best = minimize(negative, [100.2, 0.0, 0.0, math.log(0.3)], method="Nelder-Mead", options={"maxiter": 4000})
    f, rms, tau, sigma = best.x[0], *np.exp(best.x[1:])
    print(f"cycle at {f:.3f} Hz, rms {rms:.3f}, correlation time {tau:.2f} s; white noise {sigma:.3f}")  # noqa: T201

"""Posterior sampling with emcee: walkers around the MAP, run until the rank-normalized split R-hat
is <= 1.01 and the bulk and tail ESS are >= 400 for every parameter (Vehtari et al. 2021, through
ArviZ; chain = walker), with a cap; an HDF5 backend so a killed run resumes with nothing lost, a
process pool, and a progress bar whose total is the number of steps convergence is expected to
take, re-estimated at every check."""

from __future__ import annotations

import hashlib
import json
import logging
import math
import signal
import time
from collections.abc import Callable
from contextlib import contextmanager
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import emcee
import h5py
import numpy as np

from vibinverse.errors import InputError, Interrupted
from vibinverse.estimators.base import Estimator, base_result, register_estimator
from vibinverse.posterior import Posterior
from vibinverse.result import FitResult

logger = logging.getLogger(__name__)

CHECK_EVERY = 100
RHAT_MAX = 1.01  # rank-normalized split R-hat, every parameter
ESS_MIN = 400.0  # bulk and tail ESS, every parameter
LAPLACE_WEIGHT = 0.5  # the share of steps that propose from the Laplace approximation
MIN_TAUS = 20  # no convergence check before the kept chain is this many tau long


_WORKER_PROBLEM: Posterior | None = None


def _worker_log_prob(z: np.ndarray) -> float:
    """The log posterior in a pool worker: the problem is inherited once through fork, not pickled
    with every batch of walkers (which made a 2-worker pool 5x slower than none)."""
    return _WORKER_PROBLEM.log_posterior(z)


@contextmanager
def _stop_on_signals():
    flag = {"stop": False, "signum": signal.SIGINT}

    def handler(signum, frame):
        flag["stop"], flag["signum"] = True, signum

    old = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield flag
    finally:
        for s, h in old.items():
            signal.signal(s, h)


IDENTITY_ATTR = "vibinverse_identity"


def identity(problem: Posterior) -> dict[str, str]:
    """What a checkpoint belongs to: hashes of the data and the scene, the model, the free
    parameters and their priors. `--resume` continues only a checkpoint of the same."""
    series = problem.series

    def digest(data: bytes) -> str:
        return hashlib.sha256(data).hexdigest()[:16]

    return {
        "data": digest(np.ascontiguousarray(series.time).tobytes() + np.ascontiguousarray(series.intensity).tobytes()),
        "scene": digest(json.dumps(problem.model.base, sort_keys=True, default=str).encode()),
        "model": problem.model.name,
        "free parameters": ", ".join(problem.space.names),
        "priors": "; ".join(str(p) for p in problem.space.priors),
    }


class CheckpointBackend(emcee.backends.HDFBackend):
    """emcee's HDF5 backend with the steps buffered in memory and written every FLUSH_SECONDS
    (and before every read, at a convergence check, on an interruption and at the end): emcee's
    own backend opens the file for every step, which cost more than the likelihood (15 ms a step
    against 4 ms, measured on the demo). A run killed without warning loses at most the last
    FLUSH_SECONDS; Ctrl-C and SIGTERM lose nothing. The file layout is emcee's, so `--resume`
    and `emcee.backends.HDFBackend` read it unchanged."""

    FLUSH_SECONDS = 2.0

    def __init__(self, filename: str):
        super().__init__(filename)
        self._steps: list[tuple[np.ndarray, np.ndarray, Any, np.ndarray, tuple]] = []
        self._flushed = time.monotonic()
        self._stored: int | None = None  # steps in the file, read once (every read opens the file)

    @property
    def iteration(self) -> int:
        if self._stored is None:
            self._stored = int(super().iteration)
        return self._stored + len(self._steps)

    def reset(self, nwalkers, ndim) -> None:
        self._steps, self._stored = [], None
        super().reset(nwalkers, ndim)

    def save_step(self, state, accepted) -> None:
        blobs = None if state.blobs is None else np.array(state.blobs, copy=True)
        self._steps.append(
            (np.array(state.coords), np.array(state.log_prob), blobs, np.array(accepted), state.random_state)
        )
        if time.monotonic() - self._flushed >= self.FLUSH_SECONDS:
            self.flush()

    def flush(self) -> None:
        """Write the buffered steps (one file open for all of them)."""
        steps, self._steps = self._steps, []
        self._flushed = time.monotonic()
        if not steps:
            return
        self._check(emcee.State(steps[0][0], log_prob=steps[0][1], blobs=steps[0][2]), steps[0][3])
        with self.open("a") as f:
            g = f[self.name]
            first = int(g.attrs["iteration"])
            end = first + len(steps)
            if g["chain"].shape[0] < end:  # a step past what `grow` reserved
                g["chain"].resize(end, axis=0)
                g["log_prob"].resize(end, axis=0)
            g["chain"][first:end] = np.stack([st[0] for st in steps])
            g["log_prob"][first:end] = np.stack([st[1] for st in steps])
            if steps[0][2] is not None:
                g["blobs"][first:end] = np.stack([st[2] for st in steps])
            g["accepted"][:] += np.sum([st[3] for st in steps], axis=0)
            for i, v in enumerate(steps[-1][4]):
                g.attrs[f"random_state_{i}"] = v
            g.attrs["iteration"] = end
        self._stored = end

    def grow(self, ngrow, blobs) -> None:
        self.flush()
        super().grow(ngrow, blobs)

    def get_value(self, name, flat=False, thin=1, discard=0):
        self.flush()
        return super().get_value(name, flat=flat, thin=thin, discard=discard)

    def get_last_sample(self):
        self.flush()
        return super().get_last_sample()

    @property
    def accepted(self):
        self.flush()
        return super().accepted

    @property
    def random_state(self):
        self.flush()
        return super().random_state


def _open_checkpoint(path: Path, resume: bool, ident: dict[str, str]) -> CheckpointBackend:
    """emcee's HDF5 backend at `path`; one-line errors for a file that is not a checkpoint, and for
    `resume` of a checkpoint written for other data, scene, model, free parameters or priors."""
    if path.is_dir():
        raise InputError(f"--chain: {path} is a directory; give a file path for the checkpoint")
    if path.exists():
        if not h5py.is_hdf5(path):
            raise InputError(f"--chain: {path} exists and is not an HDF5 checkpoint; remove it or choose another path")
        try:
            with h5py.File(path, "r") as fh:
                stored = fh.attrs.get(IDENTITY_ATTR)
                has_chain = "mcmc" in fh
        except OSError as exc:
            raise InputError(f"--chain: cannot read the checkpoint {path}: {exc}") from None
        if not has_chain:  # a checkpoint has its chain's group from its start (`reset`): this is another file
            raise InputError(
                f"--chain: {path} is an HDF5 file without a sampler chain (a result file?), not a checkpoint; "
                "give the checkpoint (default DIR/result.chain.h5) or a new path"
            )
        if resume:
            if stored is None:
                raise InputError(
                    f"--resume: {path} carries no identity (not written by this vibinverse); "
                    "run without --resume to start afresh"
                )
            old = json.loads(stored)
            differ = [k for k in ident if old.get(k) != ident[k]]
            if differ:
                raise InputError(
                    f"--resume: the checkpoint {path} was written for other {', '.join(differ)}; "
                    "resume with the same data, scene and priors, or run without --resume"
                )
    return CheckpointBackend(str(path))


class ThreadMap:
    """emcee's `pool` for likelihoods that release the GIL (`SignalModel.releases_gil`): the walkers
    of a step are split into one block per thread, so a step costs one hand-over per
    thread instead of one message per walker (a fork pool's pipes cost more than a 0.25 ms
    likelihood). The results are in the walkers' order, so the chain is that of a serial run."""

    def __init__(self, workers: int):
        from concurrent.futures import ThreadPoolExecutor

        self.workers = workers
        self.executor = ThreadPoolExecutor(workers, thread_name_prefix="vibinverse-walker")

    def map(self, func, iterable) -> list:
        items = list(iterable)
        blocks = [items[i :: self.workers] for i in range(self.workers)]
        done = list(self.executor.map(lambda block: [func(x) for x in block], blocks))
        out = [None] * len(items)
        for i, block in enumerate(done):
            out[i :: self.workers] = block
        return out

    def close(self) -> None:
        self.executor.shutdown(wait=True)

    def join(self) -> None:
        pass


def _ignore_signals() -> None:
    """Pool workers leave SIGINT and SIGTERM to the parent, which stops them after a complete step."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)


def run(
    problem: Posterior,
    z_map: np.ndarray,
    cov_z: np.ndarray,
    backend_path: Path,
    *,
    resume: bool = False,
    nwalkers: int | None = None,
    max_steps: int = 20000,
    workers: int = 1,
    seed: int = 0,
    progress: bool = True,
) -> dict:
    """Sample until converged or `max_steps`; returns chain, log_prob, tau and the stopping facts."""
    ndim = z_map.size
    nwalkers = nwalkers or max(2 * ndim + 2, 16)
    ident = identity(problem)
    backend = _open_checkpoint(backend_path, resume, ident)
    if not resume or not backend_path.exists() or backend.iteration == 0:
        backend.reset(nwalkers, ndim)
        with h5py.File(backend_path, "a") as fh:  # before the first step: a killed run's file has it too
            fh.attrs[IDENTITY_ATTR] = json.dumps(ident)
        rng = np.random.default_rng(seed)
        chol = np.linalg.cholesky(cov_z + 1e-12 * np.eye(ndim))
        start = z_map + 0.3 * rng.normal(size=(nwalkers, ndim)) @ chol.T
        state = emcee.State(start, random_state=np.random.RandomState(seed).get_state())
    else:
        nwalkers = backend.shape[0]
        state = backend.get_last_sample()
    global _WORKER_PROBLEM
    _WORKER_PROBLEM = problem
    if workers <= 1:
        pool = None
    elif problem.model.releases_gil:
        pool = ThreadMap(workers)
    else:
        pool = get_context("fork").Pool(workers, initializer=_ignore_signals)
    check = Convergence(ndim)
    try:
        sampler = emcee.EnsembleSampler(
            nwalkers,
            ndim,
            problem if pool is None or isinstance(pool, ThreadMap) else _worker_log_prob,
            pool=pool,
            backend=backend,
            moves=moves(z_map, cov_z, lambda zs: np.array([problem.log_posterior(z) for z in zs])),
        )
        with _stop_on_signals() as flag, _progress(progress, backend.iteration, max_steps) as bar:
            check(backend)
            remaining = max_steps - backend.iteration
            if not check.converged and remaining > 0:
                for _ in sampler.sample(state, iterations=remaining, progress=False, store=True):
                    if flag["stop"]:
                        raise Interrupted(
                            f"interrupted after {backend.iteration} steps; the checkpoint {backend_path} is intact: "
                            "resume with --resume",
                            signum=flag["signum"],
                        )
                    if bar is not None:
                        bar.update(1)
                    if due(backend.iteration):
                        check(backend)
                        if bar is not None:
                            bar.total = max(min(check.expected, max_steps), backend.iteration + 1)
                            bar.set_postfix_str(check.describe(), refresh=True)
                        if check.converged:
                            break
    finally:
        backend.flush()  # every step taken is in the checkpoint, also when interrupted
        if pool is not None:
            pool.close()
            pool.join()
    converged, tau = check.converged, check.tau
    chain = backend.get_chain()
    return {
        "chain": chain,
        "log_prob": backend.get_log_prob(),
        "tau": tau,
        "converged": converged,
        "n_steps": backend.iteration,
        "nwalkers": nwalkers,
        "acceptance": float(np.mean(backend.accepted / max(backend.iteration, 1))),
    }


def split_laplace(log_posterior: Callable[[np.ndarray], np.ndarray], mean: np.ndarray, cov: np.ndarray) -> LaplaceMove:
    """The Laplace move as a split t, its scales measured on the posterior (`split_scales`, 10
    evaluations a parameter; deterministic, so a resumed run continues the same chain). On the
    demo's posterior (damping ratio 0.8 / 1.8, drive amplitude 1.0 / 2.0 on either side) the sampler
    stopped after 1400 steps instead of 2600 (three other data sets: 3200 -> 2000, 2400 -> 1600,
    1600 -> 2400). LinAlgError when the covariance is not positive definite."""
    symmetric = LaplaceMove(mean, cov)
    return LaplaceMove(mean, cov, split_scales(log_posterior, mean, symmetric.chol / symmetric.SCALE))


def moves(
    z_map: np.ndarray | None = None,
    cov_z: np.ndarray | None = None,
    log_posterior: Callable[[np.ndarray], np.ndarray] | None = None,
) -> list:
    """Differential-evolution proposals (Ter Braak 2006; Ter Braak & Vrugt 2008) mixed as emcee's
    docs suggest, which cut the autocorrelation time ~3x against the default stretch move on the
    frame posterior (its parameters are correlated); with the MAP stage's Laplace approximation,
    half the steps are independence proposals from a heavier-tailed version of it
    (`LaplaceMove`): where the posterior is near Gaussian in the unconstrained space, as it is
    for data that inform every parameter, a step then forgets where it started. Given the
    `log_posterior` (rows to values), that approximation is a split t (`split_laplace`)."""
    de = [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]
    if z_map is None or cov_z is None or not np.all(np.isfinite(cov_z)):
        return de
    try:
        laplace = LaplaceMove(z_map, cov_z) if log_posterior is None else split_laplace(log_posterior, z_map, cov_z)
    except np.linalg.LinAlgError:
        return de
    return [(m, (1 - LAPLACE_WEIGHT) * w) for m, w in de] + [(laplace, LAPLACE_WEIGHT)]


class LaplaceMove(emcee.moves.MHMove):
    """Independence Metropolis-Hastings: every walker proposes a fresh draw from a multivariate t
    (DF degrees of freedom) centred on the MAP with the Laplace covariance scaled by SCALE^2,
    accepted with the ratio of posterior to proposal densities. Its tails are heavier than a
    Gaussian posterior's, so the weights stay bounded and the chain is uniformly ergodic there; a
    fixed proposal keeps detailed balance exact (no adaptation).

    `scales` (d x 2), if given, makes it a split t (Geweke 1989): along the i-th column of the
    covariance's Cholesky factor the draw is stretched by scales[i, 0] on the positive side and
    scales[i, 1] on the negative one, each side keeping half the mass (`split_scales`
    measures them on the posterior, for a parameter whose posterior is cut by its prior)."""

    DF = 5.0
    SCALE = 1.2

    def __init__(self, mean: np.ndarray, cov: np.ndarray, scales: np.ndarray | None = None):
        self.mean = np.asarray(mean, dtype=float)
        cov = 0.5 * (cov + cov.T) * self.SCALE**2
        # the jitter is relative to each variance: one scaled by the trace widened a parameter whose
        # unconstrained sd is 1e-6 of another's (a frame's drive frequency) by 2-3x, halving the
        # effective draws of the importance check on a 5-minute record
        sd = np.sqrt(np.clip(np.diag(cov), 1e-300, None))
        corr = cov / np.outer(sd, sd) + 1e-12 * np.eye(self.mean.size)
        self.chol = sd[:, None] * np.linalg.cholesky(corr)
        self.scales = np.ones((self.mean.size, 2)) if scales is None else np.asarray(scales, dtype=float)
        if self.scales.shape != (self.mean.size, 2) or not np.all(self.scales > 0):
            raise ValueError(f"scales: {self.mean.size} x 2 positive numbers are needed")
        super().__init__(self._propose, ndim=self.mean.size)

    def _side(self, u: np.ndarray) -> np.ndarray:
        """The scale of each coordinate of whitened rows u, by the side of the mode it lies on."""
        return np.where(u >= 0, self.scales[:, 0], self.scales[:, 1])

    def log_density(self, x: np.ndarray) -> np.ndarray:
        """log of the proposal density at rows of x, up to a constant."""
        u = np.linalg.solve(self.chol, (np.atleast_2d(x) - self.mean).T).T
        side = self._side(u)
        v = u / side
        return -0.5 * (self.DF + self.mean.size) * np.log1p(np.sum(v * v, axis=1) / self.DF) - np.sum(
            np.log(side), axis=1
        )

    def draw(self, n: int, random) -> np.ndarray:
        """n draws (n, d) of the proposal (`random`: a numpy Generator or RandomState)."""
        w = np.sqrt(self.DF / random.chisquare(self.DF, size=n))
        v = random.standard_normal((n, self.mean.size)) * w[:, None]
        return self.mean + (v * self._side(v)) @ self.chol.T

    def _propose(self, coords: np.ndarray, random) -> tuple[np.ndarray, np.ndarray]:
        new = self.draw(coords.shape[0], random)
        return new, self.log_density(coords) - self.log_density(new)


#: the probes of `split_scales`, in Laplace sds along each axis: to 16, since an exponential tail's
#: matching scale keeps growing with the distance (as sqrt(delta)) and must be met where its mass is
PROBES = (1.0, 2.0, 4.0, 8.0, 16.0)
#: the smallest log posterior drop a probe is read by: a side flat out to delta gets at most 2 delta
MIN_DROP = 0.125
#: the smallest scale: a side steeper than the Laplace curvature says is still given 1/10 of it
MIN_SCALE = 0.1


def split_scales(log_posterior: Callable[[np.ndarray], np.ndarray], mean: np.ndarray, chol: np.ndarray) -> np.ndarray:
    """(d, 2) scales of a split t (Geweke 1989, "Bayesian inference in econometric models using
    Monte Carlo integration", Econometrica 57): along column i of `chol` (the Laplace covariance's Cholesky
    factor), on the positive [0] and the negative [1] side of `mean`, the largest
    delta / sqrt(2 drop(delta)) over the PROBES delta, drop the fall of the log posterior from the
    mean: 1 for a Gaussian posterior that the Laplace approximation describes, the side's own scale
    for a split normal, and growing as the side's tail is heavier. `log_posterior` maps rows to
    values; 10 d evaluations."""
    mean = np.asarray(mean, dtype=float)
    d = mean.size
    deltas = np.asarray(PROBES)
    steps = np.concatenate([sign * deltas[:, None, None] * chol.T[None, :, :] for sign in (1.0, -1.0)])
    lp = np.asarray(log_posterior(np.vstack([mean[None, :], (mean + steps).reshape(-1, d)])), dtype=float)
    if not np.isfinite(lp[0]):
        return np.ones((d, 2))
    drop = (lp[0] - lp[1:]).reshape(2, deltas.size, d)  # (side, delta, axis)
    drop = np.where(np.isfinite(drop), np.maximum(drop, MIN_DROP), np.inf)
    scale = np.max(deltas[None, :, None] / np.sqrt(2.0 * drop), axis=1)  # (side, axis)
    return np.maximum(scale, MIN_SCALE).T


def due(n: int) -> bool:
    """Whether the stopping rule is checked after step n: every CHECK_EVERY steps up to 1000, then
    every 2 CHECK_EVERY, then every 5 CHECK_EVERY past 5000 (a check costs ~0.15 s; the schedule
    depends on n alone, so a resumed run stops where an uninterrupted one does)."""
    every = CHECK_EVERY if n <= 1000 else 2 * CHECK_EVERY if n <= 5000 else 5 * CHECK_EVERY
    return n % every == 0


def burn_in(n_steps: int, tau: np.ndarray) -> int:
    """Steps dropped as burn-in: 3 autocorrelation times (the walkers start near the MAP, from the
    Laplace approximation), at most half the run."""
    return int(min(n_steps // 2, 3 * np.nanmax(tau) if np.all(np.isfinite(tau)) else n_steps // 2))


def rank_diagnostics(chains: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rank-normalized split R-hat, bulk ESS and tail ESS per parameter of (chain, draw, parameter)
    draws, as `arviz.summary` computes them (`vibinverse.inference_data`, either ArviZ major)."""
    from vibinverse.inference_data import rank_diagnostics as diagnostics

    return diagnostics(chains)


class Convergence:
    """The stopping rule, called on the backend every CHECK_EVERY steps: R-hat <= RHAT_MAX and bulk
    and tail ESS >= ESS_MIN for every parameter of the chain after burn-in. Before the kept chain
    is MIN_TAUS autocorrelation times long the rule cannot hold and is not computed; the check
    thins the chain by a quarter of tau (ESS of the thinned chain is at most that of the whole, so
    the rule stays conservative). `expected` extrapolates the steps the rule needs: ESS grows as
    the run, R-hat^2 - 1 falls as its inverse."""

    def __init__(self, ndim: int):
        self.converged = False
        self.tau = np.full(ndim, np.inf)
        self.rhat = self.ess = math.nan
        self.expected = 0

    def __call__(self, backend) -> bool:
        n = backend.iteration
        if n < CHECK_EVERY:
            self.expected = max(self.expected, 10 * CHECK_EVERY)
            return False
        self.tau = backend.get_autocorr_time(tol=0)
        tau = float(np.nanmax(self.tau)) if np.all(np.isfinite(self.tau)) else math.inf
        burn = burn_in(n, self.tau)
        if not math.isfinite(tau) or n - burn < MIN_TAUS * tau:
            self.expected = int(burn + MIN_TAUS * tau) if math.isfinite(tau) else 2 * n
            return False
        for thin in dict.fromkeys((max(1, int(tau // 4)), 1)):  # a pass on the thinned chain is confirmed whole
            rhat, bulk, tail = rank_diagnostics(backend.get_chain(discard=burn, thin=thin).transpose(1, 0, 2))
            self.rhat, self.ess = float(np.nanmax(rhat)), float(np.nanmin(np.minimum(bulk, tail)))
            self.converged = bool(self.rhat <= RHAT_MAX and self.ess >= ESS_MIN)
            if not self.converged:
                break
        if not math.isfinite(self.rhat) or not math.isfinite(self.ess):
            self.expected = 2 * n
            return False
        kept = n - burn
        need = kept * max(ESS_MIN / max(self.ess, 1.0), (self.rhat**2 - 1) / (RHAT_MAX**2 - 1), 1.0)
        self.expected = int(burn + need)
        return self.converged

    def describe(self) -> str:
        if math.isnan(self.rhat):
            return f"tau {float(np.nanmax(self.tau)):.0f}" if np.all(np.isfinite(self.tau)) else ""
        return f"R-hat {self.rhat:.3f}, ESS {self.ess:.0f}"


@contextmanager
def _progress(show: bool, done: int, cap: int):
    """A tqdm bar over the steps convergence is expected to take (or None)."""
    if not show:
        yield None
        return
    from tqdm import tqdm

    with tqdm(total=min(10 * CHECK_EVERY, cap), initial=done, desc="emcee", unit="step", leave=True) as bar:
        yield bar


def multimodal(values: np.ndarray, names: list[str], separation: float = 5.0) -> list[str]:
    """Parameters whose walkers sit in separate groups: sorted walker means with a gap wider than
    `separation` times the typical within-walker sd, and at least 2 walkers on each side. An
    ensemble sampler's walkers do not cross between well-separated modes, so this is how a second
    mode shows. values: (walker, draw, parameter)."""
    out = []
    for j, n in enumerate(names):
        means = np.sort(values[:, :, j].mean(axis=1))
        within = float(np.median(values[:, :, j].std(axis=1)))
        gaps = np.diff(means)
        k = int(np.argmax(gaps)) if gaps.size else -1
        if k >= 1 and k <= len(means) - 3 and gaps[k] > separation * max(within, 1e-300):
            out.append(n)
    return out


def sampler_diagnostics(values: np.ndarray, res: dict) -> dict:
    """The largest rank-normalized split R-hat and the smallest bulk and tail ESS over the
    parameters (ArviZ, chain = walker), emcee's tau, and whether the stopping rule holds."""
    rhat, bulk, tail = rank_diagnostics(values)
    rhat_max, ess_min = float(np.nanmax(rhat)), float(np.nanmin(np.minimum(bulk, tail)))
    return {
        "rhat_max": rhat_max,
        "ess_min": ess_min,
        "ess_bulk_min": float(np.nanmin(bulk)),
        "ess_tail_min": float(np.nanmin(tail)),
        "tau_max": float(np.nanmax(res["tau"])),
        "n_steps": int(res["n_steps"]),
        "nwalkers": int(res["nwalkers"]),
        "acceptance": res["acceptance"],
        "stopping_rule": f"R-hat <= {RHAT_MAX}, bulk and tail ESS >= {ESS_MIN:.0f}",
        "converged": bool(rhat_max <= RHAT_MAX and ess_min >= ESS_MIN),
    }


@register_estimator
class Emcee(Estimator):
    """emcee from the MAP of the stage before (its point and Laplace covariance in z), run until
    the stopping rule (`Convergence`) holds; the first min(3 tau, half) of the chain is burn-in."""

    name = "mcmc"

    def estimate(
        self,
        posterior: Posterior,
        start: FitResult | None,
        *,
        backend: Path | None = None,
        resume: bool = False,
        workers: int = 1,
        seed: int = 0,
        max_steps: int = 20000,
        progress: bool = True,
        **options: Any,
    ) -> FitResult:
        if start is None or start.z is None or start.cov_z is None:
            raise InputError("mcmc: needs a MAP start (a result with z and cov_z); run a MAP estimator first")
        backend = Path(backend or "vibinverse-chain.h5")
        logger.info("sampling with emcee (checkpoint %s) ...", backend)
        res = run(
            posterior,
            start.z,
            start.cov_z,
            backend,
            resume=resume,
            workers=workers,
            seed=seed,
            max_steps=max_steps,
            progress=progress,
        )
        chain = res["chain"]
        tau = res["tau"]
        burn = burn_in(chain.shape[0], tau)
        kept = chain[burn:]
        values = np.array([[list(posterior.values(z).values()) for z in walker] for walker in kept.transpose(1, 0, 2)])
        diagnostics = {**sampler_diagnostics(values, res), "multimodal": multimodal(values, posterior.space.names)}
        return base_result(
            posterior,
            self.name,
            start.point,
            chains=values,
            log_prob=res["log_prob"][burn:].T,
            z=start.z,
            cov_z=start.cov_z,
            log_post=start.log_post,
            diagnostics=diagnostics,
        )

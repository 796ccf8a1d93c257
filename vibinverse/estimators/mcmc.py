"""Posterior sampling with emcee: walkers around the MAP, run to >= 50 integrated autocorrelation
times (with a cap), an HDF5 backend so a killed run resumes with nothing lost, a process pool and
a progress bar."""

from __future__ import annotations

import hashlib
import json
import logging
import signal
import warnings
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
TAU_FACTOR = 50


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


def _open_checkpoint(path: Path, resume: bool, ident: dict[str, str]) -> emcee.backends.HDFBackend:
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
        if resume and has_chain:
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
    return emcee.backends.HDFBackend(str(path))


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
    pool = get_context("fork").Pool(workers, initializer=_ignore_signals) if workers > 1 else None
    converged, tau = False, np.full(ndim, np.inf)
    try:
        sampler = emcee.EnsembleSampler(
            nwalkers, ndim, _worker_log_prob if pool else problem, pool=pool, backend=backend, moves=moves()
        )
        with _stop_on_signals() as flag:
            converged, tau = _converged(backend)
            remaining = max_steps - backend.iteration
            if not converged and remaining > 0:
                for _ in sampler.sample(state, iterations=remaining, progress=progress, store=True):
                    if flag["stop"]:
                        raise Interrupted(
                            f"interrupted after {backend.iteration} steps; the checkpoint {backend_path} is intact: "
                            "resume with --resume",
                            signum=flag["signum"],
                        )
                    if backend.iteration % CHECK_EVERY == 0:
                        converged, tau = _converged(backend)
                        if converged:
                            break
    finally:
        if pool is not None:
            pool.close()
            pool.join()
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


def moves() -> list:
    """Differential-evolution proposals (Ter Braak 2006; Ter Braak & Vrugt 2008) mixed as emcee's
    docs suggest: on the frame posterior they cut the autocorrelation time ~3x against the default
    stretch move (tau ~25 against ~70 steps, measured), because its parameters are correlated."""
    return [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]


def _converged(backend) -> tuple[bool, np.ndarray]:
    """Converged when the run is >= 50 tau long for every parameter (emcee's integrated
    autocorrelation time, computed with tol=0 so that short chains still give an estimate)."""
    n = backend.iteration
    if n < CHECK_EVERY:
        return False, np.full(backend.shape[1], np.inf)
    tau = backend.get_autocorr_time(tol=0)
    return bool(np.all(np.isfinite(tau)) and n >= TAU_FACTOR * tau.max()), tau


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
    """Split R-hat and bulk ESS from ArviZ over walkers (chain = walker), emcee's tau."""
    import arviz as az

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = az.convert_to_dataset({f"p{j}": values[..., j] for j in range(values.shape[-1])})
        rhat = float(np.nanmax([az.rhat(ds)[v].item() for v in ds.data_vars]))
        ess = float(np.nanmin([az.ess(ds)[v].item() for v in ds.data_vars]))
    return {
        "rhat_max": rhat,
        "ess_min": ess,
        "tau_max": float(np.nanmax(res["tau"])),
        "n_steps": int(res["n_steps"]),
        "nwalkers": int(res["nwalkers"]),
        "acceptance": res["acceptance"],
        "converged": bool(res["converged"] and rhat < 1.05),
    }


@register_estimator
class Emcee(Estimator):
    """emcee from the MAP of the stage before (its point and Laplace covariance in z), run to
    >= 50 tau; the first max(3 tau, half) of the chain is burn-in."""

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
        burn = int(min(chain.shape[0] // 2, 3 * np.nanmax(tau) if np.all(np.isfinite(tau)) else chain.shape[0] // 2))
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

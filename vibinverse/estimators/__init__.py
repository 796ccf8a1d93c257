"""Estimators behind one interface (`Estimator.fit(posterior, start) -> FitResult`), by role:
spectral starts, SINDy identification, casadi MAP + Laplace, derivative-free MAP, emcee, and the
Laplace approximation importance-sampled (long records)."""

from vibinverse.estimators.base import ESTIMATORS, Estimator, register_estimator
from vibinverse.estimators.casadi_map import CasadiMap
from vibinverse.estimators.importance import LaplaceImportance
from vibinverse.estimators.mcmc import Emcee
from vibinverse.estimators.scipy_map import ScipyMap
from vibinverse.estimators.sindy import SindyEstimator
from vibinverse.estimators.spectral import SpectralEstimator

__all__ = [
    "ESTIMATORS",
    "CasadiMap",
    "Emcee",
    "Estimator",
    "LaplaceImportance",
    "ScipyMap",
    "SindyEstimator",
    "SpectralEstimator",
    "register_estimator",
]

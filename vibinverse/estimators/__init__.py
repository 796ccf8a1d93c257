"""Estimators that share one result type: spectral (instant, rough), MAP (+ Laplace), emcee."""

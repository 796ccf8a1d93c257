"""Likelihood engines: the one Kalman recursion every composed model runs on (`kalman`)."""

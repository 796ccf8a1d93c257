"""Benchmarks behind `vibinverse bench`: speed against error, side by side in one run."""

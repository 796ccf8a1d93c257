"""Operational modal analysis of multi-channel records: frequencies, damping ratios and mode shapes
with calibrated intervals from the multi-channel frequency-domain likelihood (`identify`)."""

from vibinverse.oma.identify import identify
from vibinverse.oma.result import OmaMode, OmaResult, mac, mac_matrix

__all__ = ["OmaMode", "OmaResult", "identify", "mac", "mac_matrix"]

"""Detection, not invention: does the data show each line the fit claims?

For every line of the model (`SignalModel.line_tests`) the log-likelihood gain of the fit over the
same fit without the line is compared with a threshold of 12.5 (5 sigma for one added line at a
known frequency) plus ln(N), N the number of independent frequencies (prior width x record span)
the fit could have put the line at: the look-elsewhere effect of a free frequency (Bonferroni over
Fourier bins). Below it the data do not show the line: the result says so.
"""

from __future__ import annotations

import math
from typing import Any

from vibinverse.posterior import Posterior

DETECTION_GAIN = 12.5  # log-likelihood gain of 5 sigma for one added line at a known frequency


def threshold(posterior: Posterior, frequency: str | None) -> float:
    """12.5, plus ln(independent frequencies in the prior) when the frequency is free."""
    series = posterior.series
    span = float(series.time[-1] - series.time[0] + series.dt)
    lo, hi = posterior.bounds.get(frequency, (0.0, 0.0)) if frequency else (0.0, 0.0)
    return DETECTION_GAIN + math.log(max(1.0, (hi - lo) * span))


def line_detection(posterior: Posterior, values: dict[str, float]) -> dict[str, Any]:
    """`{label}_delta_loglike`, `{label}_threshold` and `{label}_detected` of every line of the fit at `values`."""
    model = posterior.model
    ll = model.log_likelihood(values)
    out: dict[str, Any] = {}
    for test in model.line_tests(values, posterior.space.names):
        gain = ll - model.log_likelihood({**values, **test.null})
        limit = threshold(posterior, test.frequency)
        out.update(
            {
                f"{test.label}_delta_loglike": float(gain),
                f"{test.label}_threshold": limit,
                f"{test.label}_detected": bool(gain > limit),
            }
        )
    return out

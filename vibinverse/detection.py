"""Detection, not invention: does the data show each line the fit claims?

For every line of the model (`SignalModel.line_tests`) the log-likelihood gain of the fit over the
same fit without the line is compared with a threshold of 12.5 (5 sigma for one added line at a
known frequency) plus ln(N), N the number of independent frequencies (prior width x record span)
the fit could have put the line at: the look-elsewhere effect of a free frequency (Bonferroni over
Fourier bins). Below it the data do not show the line: the result says so.

"Without the line" is the model's maximum with the line removed (`null_optimum`: its other
parameters refitted), not the fit with only the line's amplitude set to 0: held at the fit, a
resonance next to a line cannot take back the power the line held, and the gain is overstated.
On the robustness bench's weak_drive case (a 4 Hz line next to the 3.46 Hz resonance, 50 data
sets) the held gain "detected" the line in 28, the refitted one in 10, each the same decision as
the bench's oracle (both orders fitted from the truth) on every data set. The held gain is an
upper bound of the refitted one, so the refit (a few L-BFGS-B iterations from the fit's own
point, ~0.3 s a line on 400 samples, ~0.25 s on 36 000) runs only where the held gain would claim
the line or give a false-alarm probability below REFIT_BELOW; elsewhere the held gain already
says "not detected", and the probability it gives is a lower bound.

A model that names the parameters near each line (`LineTest.near`: the modal model's components
whose band reaches it, and the broadband terms) has its null refitted over those first, the rest
held: a lower bound of the whole refit's maximum, so a gain it leaves at or below the threshold is
"not detected" as the whole refit would say. A gain of NEAR_MARGIN (10) times the threshold or more
stands as it is (a false-alarm probability below 1e-90 at any threshold): the far parameters would
have to take back nine tenths of it. In between the whole null is refitted, from the near one. On
the real beam record (63,041 samples, 6 modes and 6 lines, threshold 22.9) the near refits took
1.7 s where the whole ones took 18 s; the gains were 1,397 to 668,607 (whole: 1,367 to 668,612),
the largest difference a line at 300 Hz, 17,665 against 6,383, which a narrow mode 20 Hz away took
in part by moving onto it.

Each test also carries its false-alarm probability `{label}_false_alarm_probability`: the chance
that pure noise (no line anywhere in the prior) gives a gain at least as large as the one measured.
Under that null, twice the gain of a sinusoid with free amplitude and phase at one given frequency
is chi2 with 2 degrees of freedom (Wilks, for many samples), so P(gain > g) = exp(-g). A free frequency is
searched continuously over its prior [lo, hi]: the maximum of the gain over it exceeds g far more
often than at one frequency. Bonferroni over the N = (hi - lo) x span Fourier bins the threshold
counts, N exp(-g), is not enough: a continuous search also finds the peaks between the bins (a
simulation of pure white noise gives 12-14 % of records with N exp(-g) < 0.05, not 5 %). The bound
used is Davies' upcrossing bound in Baluev's form (Baluev 2008, MNRAS 385, 1279, for a known noise
level):

    p = exp(-g) (1 + W sqrt(g)),  W = (hi - lo) T_eff,  T_eff = sqrt(4 pi var(t)),

var(t) the variance of the sample times (gaps left out); for evenly spaced samples
T_eff = 1.02 x span, so W ~ N and p ~ N exp(-g) sqrt(g): the threshold's look-elsewhere factor
times the oversampling term sqrt(g). p is capped at 1, and is 1 for a gain <= 0 or an unbounded
frequency prior. It is an upper bound, tight in the tail (p < 0.1) that a decision uses, and it is
checked by simulation (tests/vibinverse/test_detection.py: of pure-noise records with fixed seeds,
no more than ~5 % have p < 0.05). For the frame's resonance (its base noise set to 0: one
parameter at a bound, the frequency and damping then undefined) chi2(2)/2 is an approximation of
the same kind; the simulation checks it too.

A resonance must also be one: a mode whose damping ratio exceeds BROAD_DAMPING (0.2, quality
factor under 2.5) at the fit is a broad hump of the spectrum, which a slow background (a drift, a
low-pass noise) or a mismatch of the noise's shape near Nyquist (a logger's anti-alias filter)
makes as readily as a structure. It stays in the model, is reported (`{label}_broad`) and is not
claimed: `{label}_detected` is False whatever its gain. Automated operational modal analysis
rejects such poles by the same hard criterion (damping ratio above 20 %: Reynders, Houbrechts and
De Roeck 2012, Mech. Syst. Signal Process. 29, 228). On a 90 min 10 Hz building-like record
(modes 1.73/2.00/2.23 Hz, zeta 0.006-0.012), a 0.2 Hz low-pass background three times the
modes' sd was fitted with two modes of zeta 0.5 near 0.14 and 0.25 Hz and one of zeta 0.36 at 4.5 Hz
(the simulation's filters' roll-off to Nyquist), the last claimed; a random-walk + quadratic drift
with a mode of zeta 0.66 at 0.009 Hz, claimed. A true mode of zeta 0.15 (2 Hz, 40 records of 20 s
at 20 Hz) was called broad in 1 of 40, of zeta 0.1 in none.

A tone must also be its own (`products`): a line, or a resonance as narrow as one (half-power
bandwidth 2 zeta f under TONE_BINS Fourier bins), whose frequency is within one Fourier bin (1/T) of
an integer combination sum k_i f_i (sum |k_i| from 2 to PRODUCT_ORDER = 5) of stronger detected
tones (larger gain) is their harmonic or intermodulation product, which a nonlinearity anywhere in
the chain (a shaker, a sensor, the pixel's own intensity law) makes; a free decay only when its
half-power half-width is the combination's too (sum |k_i| zeta_i f_i, within 1/T plus WIDTH_SLACK,
25 %, of the larger: a product of rings decays at the sum of their rates, and a ring's rate is
measured, where a steady tone's fitted bandwidth under a bin is not; a plucked string's fifth partial,
551.36 Hz with zeta 0.001, is within a bin of 2 x 440.70 - 3 x 110.01 Hz, but a product there would
be 2.2 times as broad). An intermodulation product
(two or more distinct tones combined) stays in the model, is named (`{label}_product`, e.g.
"2 x 100 + 120 Hz") and is not claimed. A harmonic (k x f of one tone) is named
(`{label}_harmonic`) but still claimed: a string's or a beam's higher modes sit at near-integer
multiples of the first, within a bin on a short record, and the data cannot tell them from a
distortion of the first. Only where a frequency drawn at random would match one of the
combinations with a chance of at most PRODUCT_CHANCE (5 %: their number times 2/T over the Nyquist
band) is the match taken as evidence; with many strong tones on a short record the combinations
cover the band, and nothing is read as a product. On the beam's shaker record (drive tones 100,
120, 150 Hz, 19.7 s at 3200 Hz) the fit's tones at 280, 320, 420, 440, 620 and 640 Hz are
intermodulation products (100 + 2 x 150 - 120, 2 x 100 + 120, ...), each claimed as a vibration
before, and 300 Hz is 2 x 150 (the chance of a match there: 0.7 %, 112 combinations). Of 2,000
records of three tones and a weaker fourth at random frequencies (the same span and band), the
fourth matched a combination in 0.3 %, the guard's own chance on average
(tests/vibinverse/test_detection.py). The products' frequencies match the combination of the
fitted drive frequencies to within 3-13 mHz (0.1-0.25 bins), not to within their own intervals (a
drive through a shaker is not a steady sinusoid): the bin, not the interval, is the tolerance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from vibinverse.models.base import LineTest
from vibinverse.optimize import maximize
from vibinverse.posterior import Posterior

DETECTION_GAIN = 12.5  # log-likelihood gain of 5 sigma for one added line at a known frequency
#: the null is refitted where the held gain gives a false-alarm probability below this (or passes
#: the threshold): elsewhere the held gain, an upper bound, already says "not detected"
REFIT_BELOW = 0.05
#: L-BFGS-B iterations of a null's refit (from the fit's own point, a few suffice)
REFIT_ITERATIONS = 100
#: a gain this many times the threshold after the null's refit near the line stands without the
#: whole refit (`line_detection`)
NEAR_MARGIN = 10.0
#: a resonance damped more than this is a broad hump, not claimed (module docstring)
BROAD_DAMPING = 0.2
#: a resonance narrower than this (half-power bandwidth 2 zeta f, in Fourier bins) is a tone (`products`)
TONE_BINS = 4.0
#: the highest order (sum |k_i|) of a combination of stronger tones a product is matched to
PRODUCT_ORDER = 5
#: products are read only where a random frequency would match a combination this rarely
PRODUCT_CHANCE = 0.05
#: a product's half-width is its combination's within a bin plus this fraction (`same_width`)
WIDTH_SLACK = 0.25


def threshold(posterior: Posterior, frequency: str | None) -> float:
    """12.5, plus ln(independent frequencies in the prior) when the frequency is free."""
    series = posterior.series
    span = float(series.time[-1] - series.time[0] + series.dt)
    lo, hi = posterior.bounds.get(frequency, (0.0, 0.0)) if frequency else (0.0, 0.0)
    return DETECTION_GAIN + math.log(max(1.0, (hi - lo) * span))


def false_alarm_probability(gain: float, posterior: Posterior, frequency: str | None) -> float:
    """P(a gain >= `gain` from noise alone): exp(-gain) at a fixed frequency, Davies' bound
    exp(-g) (1 + W sqrt(g)) over a free frequency's prior (module docstring), capped at 1."""
    g = float(gain)
    if math.isnan(g):
        return math.nan
    g = max(g, 0.0)
    single = math.exp(-g)
    if not frequency:
        return min(1.0, single)
    lo, hi = posterior.bounds.get(frequency, (0.0, 0.0))
    series = posterior.series
    t = np.asarray(series.time, dtype=float)[np.isfinite(series.intensity)]
    width = float(hi - lo) * math.sqrt(4.0 * math.pi * float(np.var(t))) if t.size > 1 else 0.0
    if not math.isfinite(width):
        return 1.0
    return min(1.0, single * (1.0 + width * math.sqrt(g)))


def null_optimum(posterior: Posterior, values: dict[str, float], test: LineTest, near: bool = False) -> float:
    """max ln L of the model without the line (`test.null` held), over the posterior's other free
    parameters (`near`: only the test's `near` ones, the rest held at `values`: a lower bound of
    the whole refit's maximum), from the better of `values` with the line removed and the best null
    found so far for this line (`posterior.null_optima`, updated): the stages of one fit refine one
    optimum."""
    model, space = posterior.model, posterior.space
    held = [n for n in space.names if n not in test.null and (not near or test.near is None or n in test.near)]
    starts = [{**values, **test.null}]
    if test.label in posterior.null_optima:
        starts.append({**values, **posterior.null_optima[test.label][1], **test.null})
    scored = [(model.log_likelihood(s), s) for s in starts]
    ll0, start = max(scored, key=lambda x: x[0] if math.isfinite(x[0]) else -math.inf)
    z0 = space.to_z({n: p.inside(values[n] if n in test.null else start[n]) for n, p in zip(space.names, space.priors)})
    bounded = [all(math.isfinite(b) for b in p.bounds) for p in space.priors]

    def slope(z: np.ndarray) -> np.ndarray:
        return space.gradient_z(z, model.slope({**values, **space.from_z(z), **test.null}, held) or {})

    ll, z = maximize(
        lambda z: model.log_likelihood({**values, **space.from_z(z), **test.null}),
        z0,
        [space.names.index(n) for n in held],
        bounded=bounded,
        maxiter=REFIT_ITERATIONS,
        gradient=slope if model.slope(start, []) is not None else None,
    )
    if not ll >= ll0:
        ll, found = ll0, start
    else:
        found = {**start, **space.from_z(z), **test.null}
    best = posterior.null_optima.get(test.label)
    if best is None or ll > best[0]:
        posterior.null_optima[test.label] = (ll, found)
    return max(ll, best[0]) if best is not None else ll


def line_detection(posterior: Posterior, values: dict[str, float]) -> dict[str, Any]:
    """`{label}_delta_loglike`, `{label}_threshold`, `{label}_detected`,
    `{label}_false_alarm_probability`, `{label}_frequency_parameter` (the name of its frequency,
    or None) and `{label}_null_refitted` of every line of the fit at `values`, and for a resonance
    `{label}_broad` (its damping ratio above BROAD_DAMPING: never detected). The gain is first
    taken with every other parameter held at `values` (an upper bound of the refitted gain); where
    that would claim the line, or give a false-alarm probability below REFIT_BELOW, the null is
    refitted (`null_optimum`) and the gain is ln L(values) minus the null's maximum. Made once per
    point (`Posterior.line_tests`): a refit of a long record's null takes seconds per line."""
    key = tuple(sorted((k, float(v)) for k, v in values.items()))
    if key in posterior.line_tests:
        return dict(posterior.line_tests[key])
    model = posterior.model
    ll = model.log_likelihood(values)
    out: dict[str, Any] = {}
    gains: dict[str, float] = {}
    tests = model.line_tests(values, posterior.space.names)
    for test in tests:
        gain = ll - model.log_likelihood({**values, **test.null})
        limit = threshold(posterior, test.frequency)
        broad = test.damping is not None and test.damping > BROAD_DAMPING
        refit = bool(  # a broad hump is not claimed whatever its gain: its null is not refitted
            not broad
            and math.isfinite(gain)
            and (gain > limit or false_alarm_probability(gain, posterior, test.frequency) < REFIT_BELOW)
        )
        whole = refit
        if refit and test.near is not None:  # first the parameters near it: a gain this refit
            # leaves below the limit is below it refitted in full; one NEAR_MARGIN times the limit or
            # more would need the far parameters to take back most of it (they cannot: their bands
            # do not reach the line, and the broadband terms are refitted here)
            gain = min(gain, ll - null_optimum(posterior, values, test, near=True))
            whole = limit < gain < NEAR_MARGIN * limit
        if whole:
            gain = min(gain, ll - null_optimum(posterior, values, test))
        if test.damping is not None:
            out[f"{test.label}_broad"] = bool(broad)
        gains[test.label] = float(gain)
        out.update(
            {
                f"{test.label}_delta_loglike": float(gain),
                f"{test.label}_threshold": limit,
                f"{test.label}_detected": bool(gain > limit and not broad),
                f"{test.label}_false_alarm_probability": false_alarm_probability(gain, posterior, test.frequency),
                f"{test.label}_frequency_parameter": test.frequency,
                f"{test.label}_null_refitted": refit,
            }
        )
    series = posterior.series
    span = float(series.time[-1] - series.time[0]) + series.dt
    detected = [t for t in tests if out[f"{t.label}_detected"]]
    for label, product in products(detected, gains, span, 0.5 / series.dt).items():
        if product.mixed:
            out[f"{label}_product"] = product.text
            out[f"{label}_detected"] = False
        else:
            out[f"{label}_harmonic"] = product.text
    posterior.line_tests[key] = dict(out)
    return out


def combinations(bases: list[float], order: int) -> dict[float, tuple[int, ...]]:
    """Every positive integer combination sum k_i bases_i with 2 <= sum |k_i| <= `order`, each
    frequency with its lowest-order coefficients (an enumeration bounded by the order left: 3,653
    points for six bases at order 5)."""
    out: dict[float, tuple[int, ...]] = {}

    def walk(i: int, left: int, ks: tuple[int, ...]) -> None:
        if i == len(bases):
            n = sum(abs(k) for k in ks)
            f = float(np.dot(ks, bases))
            if n >= 2 and f > 0.0 and (f not in out or n < sum(abs(k) for k in out[f])):
                out[f] = ks
            return
        for k in range(-left, left + 1):
            walk(i + 1, left - abs(k), (*ks, k))

    walk(0, order, ())
    return out


def half_width(test: LineTest) -> float:
    """A tested component's half-power half-width zeta f (Hz; 0 for a line): its decay rate / 2 pi."""
    return float(test.damping or 0.0) * float(test.hz or 0.0)


def same_width(a: float, b: float, tol: float) -> bool:
    """Whether two half-widths (Hz) agree: within a Fourier bin `tol` (a width under a bin is not
    resolved) plus WIDTH_SLACK of the larger (the fitted widths' own error)."""
    return abs(a - b) <= tol + WIDTH_SLACK * max(a, b)


def tone(test: LineTest, span: float) -> bool:
    """Whether a tested component is a tone: a line, or a resonance narrower than TONE_BINS bins."""
    if test.hz is None:
        return False
    return test.damping is None or 2.0 * test.damping * test.hz * span < TONE_BINS


@dataclass(frozen=True)
class Product:
    """A tone's combination of stronger tones: "2 x 100 + 120 Hz", and whether it mixes two or more
    of them (an intermodulation product) or is k x f of one (a harmonic)."""

    text: str
    mixed: bool


def products(tests: list[LineTest], gains: dict[str, float], span: float, nyquist: float) -> dict[str, Product]:
    """{label: Product} of each tone among `tests` (the detected ones) that lies within
    1/span of a combination (`combinations`) of the stronger tones that are not products
    themselves, and, for a free decay, whose half-width is the combination's (sum |k_i| zeta_i f_i,
    `same_width`),
    taken strongest first by `gains`, where a random frequency in (0, nyquist) would
    match one of those combinations with a chance of at most PRODUCT_CHANCE (module docstring)."""
    tol = 1.0 / span
    bases: list[LineTest] = []
    out: dict[str, Product] = {}
    for test in sorted((t for t in tests if tone(t, span)), key=lambda t: -gains[t.label]):
        hz = float(test.hz or 0.0)  # a tone has a frequency
        freqs = [float(b.hz or 0.0) for b in bases]
        combos = {f: k for f, k in combinations(freqs, PRODUCT_ORDER).items() if f < nyquist}
        widths = [half_width(b) for b in bases]
        near = [
            (sum(abs(k) for k in ks), abs(f - hz), ks)
            for f, ks in combos.items()
            if abs(f - hz) <= tol
            and (not test.ring or same_width(half_width(test), sum(abs(k) * w for k, w in zip(ks, widths)), tol))
        ]
        if near and len(combos) * 2.0 * tol / nyquist <= PRODUCT_CHANCE:
            _, _, ks = min(near)
            out[test.label] = Product(combination_text(ks, freqs), sum(k != 0 for k in ks) > 1)
        else:
            bases.append(test)
    return out


def combination_text(ks: tuple[int, ...], bases: list[float]) -> str:
    """ "100 + 2 x 150 - 120 Hz" (positive terms first)."""
    terms = sorted(((k, f) for k, f in zip(ks, bases) if k), key=lambda kf: kf[0] < 0)
    out = ""
    for k, f in terms:
        sign = (" - " if k < 0 else " + ") if out else ("-" if k < 0 else "")
        out += sign + (f"{abs(k)} x {f:.6g}" if abs(k) > 1 else f"{f:.6g}")
    return out + " Hz"

"""The order of the modal model, chosen by the data: how many resonances and lines, and whether a
drift, coloured noise and a multiplicative gain drift are there (`choose_order`).

Greedy forward selection by the Bayesian information criterion

    BIC = -2 ln L_max + k ln n      (k free parameters, n observed samples).

It starts from white noise plus a level. At each step it looks at the spectrum of the current
model's standardized one-step residuals (innovations: white where the model describes the data; on
irregular stamps a Lomb-Scargle periodogram at the stamps themselves) and proposes, at its strongest
peak, a resonance (the peak of the smoothed residual spectrum; when that peak is slow, under 10
cycles in the record, as a trend not yet described makes it, also one at the strongest peak over
the spectrum's background, `mode_peaks`) and a line (its highest bin); the
broadest mode split in two when its damping ratio exceeds 0.03 (`split_candidates`: two close modes
fitted as one hump leave no residual peak); and each nuisance term not yet in the model: a random-
walk drift, AR(1) noise, 1/f noise, a gain drift (started along the least-squares fit of its cosines
to the level's relative change, `gain_candidate`). A nuisance term is first screened on a grid of
starting values (one likelihood each) and dropped when no point of the grid gains. Each candidate is
then fitted with only its new parameters, the level and the white noise free (the rest held at the
current optimum: cheap, and a lower bound on its likelihood gain); the best `REFIT_TOP` of them (by
that partial BIC, when within 0.5 ln n of lowering it) are refitted with every parameter free, by
maximum likelihood inside the priors' support (the MAP under flat priors), in the Posterior's
unconstrained space (L-BFGS-B with finite-difference gradients, each coordinate scaled by its
curvature; a new mode from two damping starts). The candidate that lowers the BIC most is kept. When
no addition lowers it, backward and exchange moves are tried the same way (each mode, line, drift or
coloured noise removed; AR(1) and 1/f exchanged; a coloured noise and a random-walk drift exchanged;
an additive drift and a gain drift exchanged, both of which explain a changing level; a mode or
a line of under 3 cycles in the record, or a mode of damping > 0.5, exchanged for a drift or a gain
drift): the greedy forward step may take a heavily damped low-frequency mode, or a slow AR(1), for
what is AR(1) noise, or a drift, and the stepwise search undoes it. Beside a coloured noise the
white noise too must earn its place (removed, and proposed back as a forward candidate): coloured
sensor noise alone (AR(1), phi 0.9) leaves sigma unidentified, flat in ln sigma over ten units down
to its prior's bound, which cost emcee 9,500 steps and the importance sampler its Pareto check
(k 0.8). When no move lowers the BIC,
each line of under 3 cycles left is read two ways (`slow_reading`): as the line it is, and as a
gain 1 + s / level of the same curve s, which gives the same mean but makes the other modes' and
lines' amplitudes follow s. Over so few cycles nothing else tells a slow vibration from a slow
change of the gain (a cloud, an auto-exposure): BIC, comparing a 3-parameter line with a 6-cosine
gain drift that only approximates the level's change, preferred the line on a fifth of the bench's
gain-drift data sets, by 4 to 22. So the line stands only when that modulation test says it is
additive (the ratio of the two readings' likelihoods 19 : 1 or more), or when there is nothing to
modulate (no other mode or line: the two readings are then one description, and the line is the
shorter). Otherwise, multiplicative or undecided, it is a slow variation, not a detected line: it
is exchanged for the best (by BIC) of a gain drift of 6, 8 or 10 cosines and a random-walk drift,
the criterion table says so, and the search goes on without proposing components of under 3 cycles.
Last, each line is read as a resonance at its frequency and each narrow resonance (bandwidth
within 4 Fourier bins) as a line (`settle_swaps`; partial fits, refitted in full where a reading
may win or be ambiguous): the forward step keeps whichever of the two its spectral start fitted
better first, and a lightly damped resonance is as steady as a line over a short record. A reading
that lowers the BIC is taken; one less than ln 19 below in ln L (not decided at 19 : 1, as in the
modulation test) whose resonance is resolved (bandwidth of a Fourier bin or more: the record spans
more than pi decay times) is reported (`OrderResult.ambiguous`, the fit's
`diagnostics["ambiguous"]`, the report and the verdict): the data cannot tell that resonance from
a line.
Then each resonance and line whose band's envelope falls over the record is read as a free decay
(`settle_decays`: a ring from one excitation, `vibinverse.terms.decay`, its onset where the
likelihood is highest, `set_onset`), taken when it gains ln 19 in ln L (the same parameters and
frequency), plus 0.5 ln n for an onset inside the record; not on records of WHITTLE_MIN_SAMPLES or
more.
Then each resonance is tried with a line at the strongest residual peak next to it (`settle_near_lines`,
within `near_modes`' reach): a resonance that took in a weak line's power widens and moves towards
it, which hides the peak from the forward step. Such a line's frequency was searched over the
band next to the mode only (M_near = its width x span independent frequencies, ~20-50), so its
look-elsewhere term is 2 ln M_near, not the whole spectrum's 2 ln M (`OrderFit.windows`; the band
becomes the line's frequency prior in the fit, `modal.windows`, so that its detection test asks
12.5 + ln M_near too). The line is kept when it lowers that BIC (a gain of 1.5 ln n + ln M_near,
~16 at n = 4000, instead of ~20: on the bench's weak_drive data the line was kept in 10 of 50 data
sets before, and the resonance, which takes in a missed line's power, came out 0.85 % off in the
median). When it does not, but gains KEEP_GAIN (6, a 0.25 % tail) + ln M_near in ln L and lies
outside the mode's core (`in_core`: farther than two half-power half-widths, zeta f, from it), it
is kept for the resonance's estimate, not claimed: its detection test (12.5 + ln M_near, the BIC's
price) says not detected, the criterion table marks it "kept as a possible line", and the reading
without it is reported as ambiguous with the resonance's values it implies (`vi.fit` adds that
reading's 90 % intervals); the search ends there (a backward move by the BIC would take it out).
Why not the BIC here: the line is a nuisance for the resonance, and the BIC's decision is a
pre-test whose risk is largest where the line's effect is of the order of the noise. Left out,
a line that is there drags the resonance towards it (weak_drive: +0.8 % in the median over the
95 of 200 data sets without it, where the resonance's sd is ~0.5 %); put in, a line that is not
there costs only a little variance, as long as it sits beside the peak and not on it (inside the
core a "line" takes the resonance's own power: clean data set 181, the mode 3 % off). Measured on
the bench (MAP of the order search, 2026-12-04): weak_drive median error 0.635 -> 0.557 % over 200
data sets (celerite2, told of the line: 0.559); at POSSIBLE_GAIN instead of 6, 6 of 200 clean data
sets took a line next to the mode and their median went 0.415 -> 0.448 %, at 6 none did. A near
line that gains POSSIBLE_GAIN (4.5, a 1.1 % tail) + ln M_near but is not kept is reported as
ambiguous with the resonance's values it implies, and `vi.fit` adds that order's 90 % intervals.
It stops when nothing changes, or at the caps (6 modes, 6 lines); at a cap, the next candidate of
that kind is fitted alone, and when it would lower the BIC the result says so (`beyond_caps`). A
component the user fixes (`modes`, `lines`, `drift`, `noise` or `gain` in the `modal` table) is
not searched; the white
noise is searched only with the coloured noise (and not when `white` is given). On a record long
enough for Whittle's engine the gain drift is not searched: only the Kalman filter runs it (minutes
a fit at 60,000 samples); a `gain` in the table fits one. There a drift is screened and its rate
set by the filter too (`drift_by_filter`): Whittle's likelihood, on the differences, hardly sees it.

Why BIC: it is a consistent criterion for the order (the probability of choosing the true order
goes to 1 as n grows, where AIC keeps a fixed chance of adding spurious components), and its
penalty per added line or mode (3 parameters: frequency, amplitude or damping, phase or rms),
1.5 ln n in log-likelihood, is 12.4 at n = 4000: the 5-sigma gain (12.5) the detection test
(`vibinverse.detection`) asks of a line at a known frequency. A gain drift (6 cosines) costs
3 ln n: it enters when the vibration's amplitude visibly follows the level. A drift costs 0.5 ln n, AR(1) noise
ln n, 1/f noise (its level and upper corner) ln n.

Each mode and line also pays the look-elsewhere term 2 ln M, M = (Nyquist - 1 / span) x span the
independent frequencies its frequency was searched over (the term the detection test adds to its
threshold, `vibinverse.detection.threshold`): BIC's Occam factor assumes a parameter known to
within its prior's unit information, but a frequency taken at the highest of M peaks gains
~ln M from noise alone. Without it, white noise plus one line grew a spurious broad mode and a second
line in one of three seeds (each with Delta BIC of only -1 to -2).

A line within one resolution bin (1 / span) of a multiple m >= 2 of a lower line is recorded as
that line's harmonic (`harmonic_of`, `harmonic` in the components): one source.
"""

from __future__ import annotations

import functools
import logging
import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from vibinverse.errors import NumericalError
from vibinverse.io.series import FEW_CYCLES, MIN_CYCLES, Series
from vibinverse.models.modal import (
    GAIN_TERMS,
    WHITTLE_MIN_SAMPLES,
    ModalModel,
    ModalSpec,
    background,
    gain_basis,
    gain_names,
    mode_start,
    smooth,
    spectrum,
    wrap_phase,
)
from vibinverse.optimize import maximize, maximize_near
from vibinverse.parallel import thread_map
from vibinverse.priors import ParameterSpace
from vibinverse.terms.decay import envelope_decay, excitation_onset, ring_start
from vibinverse.terms.drift import RandomWalk
from vibinverse.terms.noise import AR1, ColouredNoise
from vibinverse.terms.nuisance import DRIFT_TERMS, NO_DRIFT, NO_NOISE, NOISE_TERMS

logger = logging.getLogger(__name__)

MAX_MODES = 6
MAX_LINES = 6
REFIT_TOP = 2  # candidates refitted with every parameter free, per step
#: a mode this broad is also tried as two (`split_candidates`); at 0.05 two modes 0.39 Hz apart near
#: 2.1 Hz (20 min decimated building records) were one mode of zeta 0.036-0.0499, never split, and
#: the search ended with two of three modes in 2 of 10 data sets
SPLIT_DAMPING = 0.03
SLOW_DAMPING = 0.5  # a mode this damped (or of under FEW_CYCLES cycles) is also tried as a drift
#: a mode or line whose band's envelope falls by a factor e^-0.5 (to 61 %) or more over the ring
#: (the record from its onset), read from its first third to its last, is also read as a free decay
#: (`decay_readings`; a cheap gate: the likelihood decides)
DECAY_ENVELOPE_FALL = 0.5
#: a decay reading's onsets: every ONSET_STEP of the record over its first ONSET_REACH (`decay_readings`)
ONSET_STEP, ONSET_REACH = 0.02, 0.75
SEARCHED = ("modes", "lines", "drift", "noise", "gain")
NEAR_BANDWIDTHS, NEAR_BINS = 3.0, 4.0  # a mode this close to a new component is refitted with it (`near_modes`)
SWAP_BINS = 4.0  # a resonance this narrow (2 zeta f x span, in Fourier bins) is also read as a line (`swapped`)
#: a reading 19 times likelier than the other (95 %) is decided (`slow_reading`, `settle_swaps`)
DECIDED = math.log(19.0)
REPLICATES = 8  # draws of each reading for the modulation test's expected ratio
#: a line next to a resonance that gains this much in ln L over the local look-elsewhere term (a
#: 2-dof chi-square tail of e^-4.5 = 1.1 %: "3 sigma") is a possible line (`settle_near_lines`)
POSSIBLE_GAIN = 4.5
#: a possible line next to a resonance that gains this much over the local look-elsewhere term (a
#: 2-dof tail of e^-6 = 0.25 %) is kept in the model for the resonance's estimate, not claimed
#: (`settle_near_lines`; the module docstring says why 6 and not POSSIBLE_GAIN)
KEEP_GAIN = 6.0
#: a line this close to its resonance, in half-power half-widths (zeta f; the resonance's spectral
#: density is above a fifth of its peak there), takes the resonance's place rather than sitting
#: beside it: not kept for the estimate (`in_core`)
CORE_HALF_WIDTHS = 2.0
#: a mode is also proposed at the residual's strongest peak over its background when its strongest
#: bin lies under this many cycles in the record, farther than PEAK_APART bins away (`mode_peaks`)
SLOW_PEAK_CYCLES = 10.0
PEAK_APART = 3
#: the search's fits of a long record by Whittle's likelihood group its periodogram's ordinates
#: (`search_bins`): at least SEARCH_GROUPS groups remain, and each resonance's half-power
#: half-width zeta f spans at least GROUPS_PER_HALF_WIDTH groups
SEARCH_GROUPS = 32768
GROUPS_PER_HALF_WIDTH = 10.0
#: a drift's rate set by the filter (`drift_by_filter`) stops where one more run gains at most this
#: in ln L by the parabola through the last three (under a twentieth of the cheapest price, 0.5 ln n)
FILTER_TOL = 0.25
#: a start whose white noise has collapsed, its sigma under this fraction of the record's floor
#: (`vibinverse.spectrum.white_floor`), is also fitted from sigma at half the floor (`revived`)
COLLAPSED_SIGMA = 1e-3


def band_frequencies(band: tuple[float, float], span: float) -> float:
    """The independent frequencies in `band` (lo, hi) Hz over a record of `span` s (at least 1)."""
    return max(1.0, (band[1] - band[0]) * span)


def near_reach(frequency: float, damping_ratio: float, span: float) -> float:
    """How far (Hz) a resonance's band reaches either side: NEAR_BANDWIDTHS half-power bandwidths
    (2 zeta f) plus NEAR_BINS Fourier bins (1 / span). A new component this close is refitted with
    the mode (`near_modes`) and a line is searched next to it within it (`near_band`)."""
    return NEAR_BANDWIDTHS * 2.0 * damping_ratio * frequency + NEAR_BINS / max(span, 1e-12)


def near_band(frequency: float, damping_ratio: float, span: float, nyquist: float) -> tuple[float, float]:
    """The band (lo, hi) Hz in which `settle_near_lines` searches a line next to a resonance: its
    `near_reach` either side, clipped to [MIN_CYCLES / span, nyquist]. Its `band_frequencies` are the
    line's look-elsewhere count M_near."""
    reach = near_reach(frequency, damping_ratio, span)
    return max(frequency - reach, MIN_CYCLES / span), min(frequency + reach, nyquist)


@dataclass
class OrderFit:
    """One fitted order: its model, the optimum, ln L there, k, and the BIC."""

    spec: ModalSpec
    model: ModalModel
    values: dict[str, float]
    log_likelihood: float
    k: int
    n: int
    #: the bands next to a resonance in which `settle_near_lines` found a line, (lo, hi) Hz
    windows: tuple[tuple[float, float], ...] = ()

    @functools.cached_property
    def whittle_log_likelihood(self) -> float:
        """Whittle's ln L at the optimum on every ordinate (the fit's model may have grouped them):
        what a nuisance candidate's screen compares its grid with on a long record (`screen`),
        computed once for the step's candidates."""
        return ModalModel({"modal": self.spec.table()}, self.model.series).log_likelihood(self.values)

    @property
    def bic(self) -> float:
        """BIC plus the look-elsewhere term: 2 ln M for each mode, decay and line, M the independent
        frequencies searched (module docstring): the whole spectrum's, or for a line inside one of
        `windows` the window's (its width x span, at least 1)."""
        whole = math.log(self.model.frequencies_searched)
        look = (self.spec.modes + self.spec.decays) * whole
        for j in range(self.spec.lines):
            f = self.values[f"lines[{j}].frequency"]
            inside = [band_frequencies(w, self.model.span) for w in self.windows if w[0] <= f <= w[1]]
            look += math.log(inside[0]) if inside else whole
        return -2.0 * self.log_likelihood + self.k * math.log(self.n) + 2.0 * look


@dataclass
class OrderResult:
    """The chosen order: its fit, the criterion table (each step: what was tried, its BIC, kept or
    not) and the fitted components; `table()` is the `modal` table of the chosen order, with the
    optimum as its starting point."""

    fit: OrderFit
    criterion: list[dict[str, Any]] = field(default_factory=list)
    seconds: float = 0.0
    ambiguous: list[dict[str, Any]] = field(default_factory=list)
    #: the fitted order of each ambiguous reading that is a possible line next to a resonance, by its
    #: entry's "alternative" (`settle_near_lines`): the fit refits it for its intervals
    readings: dict[str, OrderFit] = field(default_factory=dict)
    #: each kind (modes, lines) the search stopped at the cap of while one more would have lowered
    #: the BIC (`beyond_caps`): {"kind", "cap", "what", "delta_bic"}
    capped: list[dict[str, Any]] = field(default_factory=list)

    @property
    def spec(self) -> ModalSpec:
        return self.fit.spec

    @property
    def values(self) -> dict[str, float]:
        return self.fit.values

    @property
    def components(self) -> list[dict[str, Any]]:
        return self.fit.model.components(self.fit.values)

    @property
    def held(self) -> dict[str, float]:
        """The chosen fit's values its Whittle's likelihood cannot measure, which the fit after the
        search holds where the filter set them (`drift_by_filter`): a drift's rate on a long record
        ({} on the filter's engine). Whittle's posterior of the rate would be a false promise: on the
        one-hour record its 90 % interval, 0.061-0.067, missed the true 0.0707 (the filter's 0.069).
        And each free decay's amplitude, the scale of its initial state's prior: one ring is one
        draw of that state, so its posterior is skewed and wide (a Gumbel in its log); sampled with
        the rest, a plucked string's five (12,000 samples) left the importance sampler 130
        effective draws of 2,000 and sent the fit to emcee. Held at the search's maximum (empirical
        Bayes), the frequencies' and damping ratios' intervals are the data's given the ring."""
        return {n: v for n, (v, _) in self.held_why.items()}

    @property
    def held_why(self) -> dict[str, tuple[float, str]]:
        """`held` with why each is held: {name: (value, why)}."""
        spec, values = self.fit.spec, self.fit.values
        ring = "a free decay's initial amplitude scale (one ring is one draw of it), held at its maximum likelihood"
        out = {f"decays[{j}].amplitude": (float(values[f"decays[{j}].amplitude"]), ring) for j in range(spec.decays)}
        if self.fit.model.spectral is not None:
            whittle = "set by the Kalman filter's likelihood; Whittle's cannot measure it"
            out |= {n: (float(values[n]), whittle) for n in spec.drift_names if n in values}
        return out

    def table(self) -> dict[str, Any]:
        """The chosen order's `modal` table: its start the optimum, with the windows of the lines
        found next to a resonance (their frequency priors; `ModalModel.default_priors`)."""
        windows = {"windows": [list(w) for w in self.fit.windows]} if self.fit.windows else {}
        return {"modal": {**self.fit.spec.table(), "start": dict(self.fit.values), **windows}}


def sort_labels(values: dict[str, float], spec: ModalSpec) -> dict[str, float]:
    """The same model with its modes, its lines and its decays, renumbered by increasing frequency (the
    labelling `ModalModel.log_likelihood` accepts)."""
    out = dict(values)
    for kind, count, fields in (
        ("modes", spec.modes, ("frequency", "damping_ratio", "rms")),
        ("lines", spec.lines, ("frequency", "amplitude", "phase")),
        ("decays", spec.decays, ("frequency", "damping_ratio", "amplitude")),
    ):
        if count < 2:
            continue
        items = [tuple(values[f"{kind}[{i}].{f}"] for f in fields) for i in range(count)]
        for i, item in enumerate(sorted(items)):
            for f, v in zip(fields, item):
                out[f"{kind}[{i}].{f}"] = v
    return out


def fit_order(
    series: Series,
    spec: ModalSpec,
    starts: list[dict[str, float]],
    free: list[str] | None = None,
    maxiter: int = 300,
    ftol: float = 1e-10,
    windows: tuple[tuple[float, float], ...] = (),
    drift_set: bool = False,
) -> OrderFit:
    """Maximum likelihood of `spec` inside its default priors' support, from each start (the
    parameters not in `free` held at the start's values), in the unconstrained space of the priors
    (logit; L-BFGS-B with finite-difference gradients); the modes and lines sorted by frequency.
    `windows`: the near-line bands of the order it derives from (`OrderFit.windows`). By Whittle's
    engine a drift's rate is set by the filter (`drift_by_filter`), unless `drift_set`: the
    start's rate is already the filter's (a refit of a move that did not touch the drift), held."""
    # the first start is the model's (`ModalModel.value`): each line's phase prior is centred on it,
    # and no spectral guess is computed for a start that names every parameter
    model = ModalModel({"modal": {**spec.table(), "start": dict(starts[0]) if starts else {}}}, series)
    starts = revived(series, spec, starts, model.sd)
    bins = search_bins(model, starts)
    if bins > 1:
        model.start_engine(bins)
    space = ParameterSpace(model.default_priors())
    names = space.names
    free = [n for n in names if free is None or n in free]
    # Whittle's engine cannot set a drift's rate: it is held there, and the filter sets it after
    held = set(spec.drift_names) if model.spectral is not None else set()
    optimized = [n for n in free if n not in held]
    pos = [names.index(n) for n in optimized]
    best: tuple[float, dict[str, float]] | None = None
    for start in starts:
        start = {n: p.inside(_wrapped(n, start.get(n, p.centre()), p.centre())) for n, p in zip(names, space.priors)}
        z0 = space.to_z(apart(start, spec))

        ll, z = maximize(
            lambda z: model.log_likelihood(sort_labels(space.from_z(z), spec)),
            z0,
            pos,
            maxiter=maxiter,
            ftol=ftol,
            gradient=None
            if model.slope(start, []) is None
            else lambda z: space.gradient_z(z, model.slope(space.from_z(z), optimized) or {}),
        )
        if best is None or ll > best[0]:
            best = (ll, sort_labels(space.from_z(z), spec))
    if best is None or not math.isfinite(best[0]) or best[0] <= -1e299:
        raise NumericalError(f"model order: no finite likelihood for {spec}")
    # orders are compared by the exact ln L at their optimum, whichever engine found it
    values, ll = best[1], best[0]
    if model.spectral is not None:
        values, ll = drift_by_filter(model, space, values, [n for n in free if n in held and not drift_set])
    return OrderFit(spec, model, values, ll, len(names), model.n_obs, windows)


def apart(values: dict[str, float], spec: ModalSpec) -> dict[str, float]:
    """The values with no two frequencies of a kind equal (a later one moved up by 1e-6 of its
    value until it differs from every earlier one); their order is kept (a candidate's new mode is
    last, whatever its frequency: the likelihood sorts them). Why: two slow modes below the prior's
    lower edge, moved to it by `Prior.inside`, were one frequency, where the likelihood is -inf (the
    label-switching constraint), and the search's fit of a 20 min record failed with no finite ln L."""
    out = dict(values)
    for kind, count in (("modes", spec.modes), ("lines", spec.lines), ("decays", spec.decays)):
        seen: list[float] = []
        for i in range(count):
            name = f"{kind}[{i}].frequency"
            if name not in out:
                continue
            while out[name] in seen:
                out[name] += 1e-6 * max(abs(out[name]), 1e-12)
            seen.append(out[name])
    return out


def revived(series: Series, spec: ModalSpec, starts: list[dict[str, float]], sd: float) -> list[dict[str, float]]:
    """The starts, each whose white noise has collapsed (`COLLAPSED_SIGMA`) followed by a copy with
    sigma at half the record's floor. Why: once a broad first mode has taken the whole spectrum the
    search's fit puts sigma at ~1e-6 of the data's, where ln L is flat in log sigma (the noise's
    share ~ sigma^2), and every later fit started there kept it: on a decimated 90 min building
    record the three modes' fit ended 28 in ln L below the optimum, one damping ratio 20 % high
    and its interval off the truth."""
    if not spec.white or not any(s.get("noise.sigma", math.inf) < COLLAPSED_SIGMA * sd for s in starts):
        return starts
    from vibinverse.spectrum import white_floor

    floor = white_floor(series)
    if floor is None or not floor > 0.0:
        return starts
    out = []
    for s in starts:
        out.append(s)
        if s.get("noise.sigma", math.inf) < COLLAPSED_SIGMA * floor:
            out.append({**s, "noise.sigma": 0.5 * floor})
    return out


def drift_by_filter(
    model: ModalModel, space: ParameterSpace, values: dict[str, float], free: list[str]
) -> tuple[dict[str, float], float]:
    """An optimum of Whittle's likelihood with its drift's rate (when in `free`) set by the Kalman
    filter's exact ln L, the rest held, and that ln L. Why: Whittle's engine works on the
    differences, where a walk's level path is hidden under the end-to-end jump at the low
    ordinates (`shared_jump`: 2 v / m of each ordinate's power, as large as the walk's own increments), so it
    cannot set the rate: on an hour at 200 Hz with a quadratic + random-walk drift the filter puts
    3 modes and a walk of rate 0.01 32,000 in ln L above the same modes without it, where Whittle's
    says the walk loses 300 (the search took two modes of one cycle per record for the trend). A
    local search over the log rate from the start's, inside the prior's support
    (`optimize.maximize_near`): 3-6 filter runs of 0.06-0.25 s at 720,000 samples."""
    ll = model.exact_log_likelihood(values)
    if len(free) != 1:
        return values, ll
    name = free[0]
    lo, hi = (math.log(b) for b in space.priors[space.names.index(name)].bounds)
    x0 = min(max(math.log(max(values[name], 1e-300)), lo), hi)
    exact = lambda x: model.exact_log_likelihood({**values, name: math.exp(x)})
    best, x = maximize_near(exact, x0, ll, (lo, hi), tol=FILTER_TOL)
    return ({**values, name: math.exp(x)}, best) if best > ll else (values, ll)


def groupable(model: ModalModel) -> bool:
    """Whether the record is long enough for the search to group its ordinates (`search_bins`):
    Whittle's engine with at least 2 x SEARCH_GROUPS ordinates (~131,000 samples)."""
    return model.spectral is not None and (model.spectral.m // 2) // SEARCH_GROUPS >= 2


def search_bins(model: ModalModel, starts: list[dict[str, float]]) -> int:
    """How many ordinates a group of the search's Whittle periodogram holds (`Periodogram`'s
    `bins`; 1: each its own): as many as leave SEARCH_GROUPS groups, fewer where a resonance of the
    starts is narrow (its half-width zeta f over GROUPS_PER_HALF_WIDTH groups). Why: on a record of
    hundreds of thousands of samples the density at every ordinate is most of a fit's cost (one
    hour at 200 Hz: 8 ms a likelihood, 0.9 ms in groups of 10, ln L 0.7 apart at the truth), and
    the search only ranks orders: each fit's exact ln L (the Kalman filter's) decides, and the fit
    that follows the search runs the exact Whittle likelihood from its optimum."""
    sp = model.spectral
    if not groupable(model) or not starts:
        return 1
    cap = (sp.m // 2) // SEARCH_GROUPS
    step = (model.t[-1] - model.t[0]) / (model.t.size - 1)
    widths = [
        start[f"modes[{i}].frequency"] * start[f"modes[{i}].damping_ratio"]
        for start in starts
        for i in range(model.spec.modes)
        if f"modes[{i}].frequency" in start and f"modes[{i}].damping_ratio" in start
    ]
    half = min(widths, default=math.inf) * sp.m * step  # the narrowest half-width, in ordinates
    return int(max(1, min(cap, math.floor(half / GROUPS_PER_HALF_WIDTH)))) if math.isfinite(half) else cap


def _wrapped(name: str, value: float, centre: float) -> float:
    """A line's phase wrapped into the period around `centre` (its prior's window: a start past it
    is the same line, not a start to clip at the edge); any other value as it is."""
    return centre + wrap_phase(value - centre) if name.endswith(".phase") else value


@dataclass
class Candidate:
    what: str
    spec: ModalSpec
    starts: list[dict[str, float]]
    new: list[str]


def innovations(e: np.ndarray, lk: np.ndarray) -> np.ndarray:
    """The one-step prediction errors in intensity units (NaN at gaps) from a model's standardized
    residuals `e` and pointwise log densities `lk` (`ModalModel.filtered`): e x sqrt(innovation
    variance), the variance recovered from the log density."""
    s = np.exp(-2.0 * lk - math.log(2.0 * math.pi) - e * e)
    return e * np.sqrt(s)


def candidates(
    fit: OrderFit, series: Series, search: dict[str, bool], caps: tuple[int, int], cycles: float = MIN_CYCLES
) -> list[Candidate]:
    """What to try next (module docstring): a mode and a line at the residual spectrum's strongest
    peak of at least `cycles` cycles in the record, and each nuisance term the model lacks."""
    spec, values = fit.spec, fit.values
    model = fit.model
    dt = float(model.steps[0]) if model.steps.size == 1 else series.dt
    span = max(model.span, dt)
    lo, nyq = cycles / span, min(0.5 / dt, series.top)
    e, lk = model.filtered(values)
    freqs, power = spectrum(e, dt, model.t)
    band = (freqs >= lo) & (freqs < 0.999 * nyq)
    out: list[Candidate] = []
    v = innovations(e, lk)
    vf, vp = spectrum(v, dt, model.t)
    floor = float(np.median(vp[band])) / math.log(2.0)
    sigma = noise_rms(values)
    if search["modes"] and spec.modes < caps[0] and band.any():
        sm = smooth(power, 7)
        k = spec.modes
        new = [f"modes[{k}].frequency", f"modes[{k}].damping_ratio", f"modes[{k}].rms"]
        for f in mode_peaks(freqs[band], sm[band], span):
            zeta, rms = mode_start(vf, vp, f, model.n_obs, floor)
            starts = [{**values, new[0]: f, new[1]: z, new[2]: rms} for z in sorted({zeta, 0.01, 0.05})[:2]]
            out.append(Candidate(f"mode at {f:.4g} Hz", replace(spec, modes=k + 1), starts, new))
    if search["modes"] and 0 < spec.modes < caps[0]:
        out += split_candidates(spec, values, nyq)
    if search["lines"] and spec.lines < caps[1] and band.any():
        from vibinverse.spectrum import sinusoid, strongest_sinusoid

        i = int(np.flatnonzero(band)[np.argmax(power[band])])
        df = freqs[1] - freqs[0]
        y0 = model.y - model.mean(values)
        fine = np.linspace(freqs[i] - df, freqs[i] + df, 41)
        f = strongest_sinusoid(model.t, y0, fine)
        a, ph, _ = sinusoid(model.t, y0, f)
        k = spec.lines
        new = [f"lines[{k}].frequency", f"lines[{k}].amplitude", f"lines[{k}].phase"]
        out.append(
            Candidate(
                f"line at {f:.6g} Hz", replace(spec, lines=k + 1), [{**values, new[0]: f, new[1]: a, new[2]: ph}], new
            )
        )
    sd = float(np.nanstd(v))
    if search["drift"] and not spec.drifting:
        grid = [{**values, "drift.rate": c * sd / math.sqrt(span)} for c in (0.03, 0.1, 0.3, 1.0, 3.0)]
        out.append(Candidate("drift (random walk)", replace(spec, drift=RandomWalk.kind), grid, ["drift.rate"]))
    if search["noise"] and not spec.coloured:
        for kind, noise in coloured_noises():  # each screened on its own grid (`ColouredNoise.screen_starts`)
            grid = [{**values, **g} for g in noise.screen_starts(sigma, dt, span)]
            out.append(Candidate(noise.label, replace(spec, noise=kind), grid, noise.names()))
    if search.get("white") and not spec.white:
        grid = [{**values, "noise.sigma": c * sigma} for c in (0.03, 0.1, 0.3)]
        out.append(Candidate("white noise", replace(spec, white=True), grid, ["noise.sigma"]))
    if search["gain"] and not spec.gain:
        out.append(gain_candidate(model, values, spec))
    return out


def mode_peaks(freqs: np.ndarray, sm: np.ndarray, span: float) -> list[float]:
    """Where a new mode is proposed: the smoothed residual spectrum's strongest bin, and when that
    bin is slow (under SLOW_PEAK_CYCLES cycles in the record) also its strongest bin over its
    background (`background`), when that lies farther than PEAK_APART bins from it. Why: a trend
    the model does not yet describe puts the residual's power at its lowest bins; on an hour with a
    quadratic drift (3.1, 7.4, 12.9 Hz modes) the only mode proposed sat there at every step (2 cycles),
    AR(1) noise took the 7.4 and 12.9 Hz modes' power instead, and the search ended with one mode
    of three. A resonance stands above the background where a drift's power law does not."""
    i = int(np.argmax(sm))
    out = [float(freqs[i])]
    if freqs[i] * span < SLOW_PEAK_CYCLES and freqs.size > 2 * PEAK_APART:
        j = int(np.argmax(sm / background(freqs, sm)))
        if abs(j - i) > PEAK_APART:
            out.append(float(freqs[j]))
    return out


def coloured_noises() -> list[tuple[str, ColouredNoise]]:
    """(table spelling, term) of each coloured noise, in the registry's order (`NOISE_TERMS`)."""
    return [(kind, cls()) for kind, cls in NOISE_TERMS.items() if cls is not None]


def noise_rms(values: dict[str, float]) -> float:
    """The white noise's sigma, or without white noise the coloured noise's rms: the noise's scale."""
    for name in ("noise.sigma", *(noise.rms_name for _, noise in coloured_noises())):
        if name in values:
            return values[name]
    raise KeyError("noise.sigma")


def split_candidates(spec: ModalSpec, values: dict[str, float], nyq: float) -> list[Candidate]:
    """The broadest mode, when its damping ratio exceeds SPLIT_DAMPING (and is not nearly critical,
    SLOW_DAMPING: such a hump is a drift or coloured noise, `neighbours`), split into two at its
    half-power points f (1 -+ zeta), each a third of its damping and half its variance: two close
    resonances fitted as one broad hump (three ambient modes within 1.6-2.7 Hz became a mode and a
    hump of zeta 0.12-0.19) are not found otherwise, because the residual spectrum then shows no
    peak where the hump sits."""
    k = spec.modes
    zetas = [values[f"modes[{i}].damping_ratio"] for i in range(k)]
    i = int(np.argmax(zetas))
    zeta, f = zetas[i], values[f"modes[{i}].frequency"]
    if not SPLIT_DAMPING < zeta <= SLOW_DAMPING or f * (1 + zeta) >= nyq:
        return []
    rms = values[f"modes[{i}].rms"] / math.sqrt(2.0)
    start = dict(values)
    for j, ff in ((i, f * (1 - zeta)), (k, f * (1 + zeta))):
        start[f"modes[{j}].frequency"], start[f"modes[{j}].damping_ratio"], start[f"modes[{j}].rms"] = ff, zeta / 3, rms
    new = [f"modes[{j}].{p}" for j in (i, k) for p in ("frequency", "damping_ratio", "rms")]
    return [Candidate(f"split the mode at {f:.4g} Hz (zeta {zeta:.2g})", replace(spec, modes=k + 1), [start], new)]


def gain_candidate(model: ModalModel, values: dict[str, float], spec: ModalSpec) -> Candidate:
    """A multiplicative gain drift of GAIN_TERMS cosines, started on a grid along the least-squares
    fit of the cosines to the relative change of the level (`ModalModel.gain_start`): 1/2, 1 and
    3/2 of it, and, when a drift is in the model (it may already hold the level's change), the same
    with the drift's rate a tenth."""
    coef = model.gain_start(GAIN_TERMS)
    grid = [{**values, **_gain_values(coef * k)} for k in (0.5, 1.0, 1.5)]
    if spec.drifting:
        grid += [{**g, "drift.rate": 0.1 * values["drift.rate"]} for g in grid]
    return Candidate("gain drift (multiplicative)", replace(spec, gain=GAIN_TERMS), grid, gain_names(GAIN_TERMS))


def _gain_values(coef: np.ndarray) -> dict[str, float]:
    """{gain.a1: ..., gain.aJ: ...} of the coefficients `coef`."""
    return {n: float(c) for n, c in zip(gain_names(len(coef)), coef)}


def screen(series: Series, current: OrderFit, c: Candidate) -> tuple[Candidate, float]:
    """A nuisance candidate's best starting point on its grid of starts (no optimization: one
    likelihood each), and the gain in ln L there over the current fit, both by the same engine
    (on a long record Whittle's; the current fit's ln L is the filter's, whose difference from
    Whittle's depends on the model by thousands on a trended record). A term that gains nothing
    anywhere on a grid spanning its plausible range is not worth an optimization."""
    model = ModalModel({"modal": c.spec.table()}, series)
    # a drift is scored by the filter on both sides (Whittle's engine cannot see it: `drift_by_filter`)
    exact = model.spectral is None or bool(set(c.spec.drift_names) & set(c.new))
    score = model.exact_log_likelihood if exact else model.log_likelihood
    scored = [(score(sort_labels(st, c.spec)), st) for st in c.starts]
    ll, st = max(scored, key=lambda s: s[0] if math.isfinite(s[0]) else -math.inf)
    base = current.log_likelihood if exact else current.whittle_log_likelihood
    return replace(c, starts=[st]), ll - base


def renumber(values: dict[str, float], kind: str, drop: int, count: int) -> dict[str, float]:
    """`values` without component `drop` of `kind` ("modes", "lines" or "decays"), the later ones shifted down."""
    out = {n: v for n, v in values.items() if not n.startswith(f"{kind}[")}
    for i, j in enumerate(k for k in range(count) if k != drop):
        for n, v in values.items():
            if n.startswith(f"{kind}[{j}]."):
                out[f"{kind}[{i}]." + n.split(".", 1)[1]] = v
    return out


def neighbours(fit: OrderFit, series: Series, search: dict[str, bool]) -> list[Candidate]:
    """The backward and exchange moves from the current order: each mode, line, drift or coloured
    noise removed, the coloured noise exchanged for the other kind, and a coloured noise exchanged
    for a random-walk drift (and back): a slow AR(1) and a random walk, or a heavily damped
    low-frequency mode and AR(1) noise, describe much the same spectrum, and the greedy forward
    step may have taken the wrong one first."""
    spec, values = fit.spec, fit.values
    sigma = noise_rms(values)
    with_white = {"noise.sigma": sigma, **values}  # a start that brings the white noise back
    span = max(fit.model.span, series.dt)
    out: list[Candidate] = []
    # every drift's and coloured noise's parameters (the registries' order), the gain drift's
    kinds = (cls() for cls in (*DRIFT_TERMS.values(), *NOISE_TERMS.values()) if cls is not None)
    nuisance = [*dict.fromkeys(n for term in kinds for n in term.names()), *gain_names(max(GAIN_TERMS, spec.gain))]

    def move(what: str, new_spec: ModalSpec, starts: list[dict[str, float]]) -> Candidate:
        names = set(new_spec.names())
        back = ["noise.sigma"] if new_spec.white and not spec.white else []  # the white noise brought back
        return Candidate(what, new_spec, starts, [n for n in nuisance if n in names] + back)

    if search.get("decays", True) and (search["modes"] or search["lines"]):
        for j in range(spec.decays):
            f = values[f"decays[{j}].frequency"]
            start = renumber(values, "decays", j, spec.decays)
            out.append(move(f"remove the free decay at {f:.4g} Hz", replace(spec, decays=spec.decays - 1), [start]))
    if search["modes"]:
        for i in range(spec.modes):
            f = values[f"modes[{i}].frequency"]
            start = renumber(values, "modes", i, spec.modes)
            out.append(move(f"remove the mode at {f:.4g} Hz", replace(spec, modes=spec.modes - 1), [start]))
            slow = f * span < FEW_CYCLES or values[f"modes[{i}].damping_ratio"] > SLOW_DAMPING
            if slow and search["drift"] and not spec.drifting:
                # a mode of under 3 cycles in the record, or nearly critically damped, may be a drift
                rate = values[f"modes[{i}].rms"] / math.sqrt(span)
                out.append(
                    move(
                        f"the mode at {f:.4g} Hz exchanged for a random-walk drift",
                        replace(spec, modes=spec.modes - 1, drift=RandomWalk.kind),
                        [{**start, "drift.rate": rate * k} for k in (0.3, 1.0)],
                    )
                )
            if slow and search["gain"] and not spec.gain:
                # ... or a slow change of the gain (the level's change, the vibration with it)
                out.append(
                    move(
                        f"the mode at {f:.4g} Hz exchanged for a gain drift",
                        replace(spec, modes=spec.modes - 1, gain=GAIN_TERMS),
                        [{**start, **_gain_values(fit.model.gain_start(GAIN_TERMS))}],
                    )
                )
    if search["lines"]:
        for j in range(spec.lines):
            f = values[f"lines[{j}].frequency"]
            start = renumber(values, "lines", j, spec.lines)
            out.append(move(f"remove the line at {f:.6g} Hz", replace(spec, lines=spec.lines - 1), [start]))
            if f * span >= FEW_CYCLES:
                continue
            # a line of under 3 cycles in the record may be a slow change of the level
            fewer = replace(spec, lines=spec.lines - 1)
            amp = values[f"lines[{j}].amplitude"]
            if search["drift"] and not spec.drifting:
                rates = [{**start, "drift.rate": amp / math.sqrt(span) * k} for k in (0.3, 1.0)]
                out.append(
                    move(
                        f"the line at {f:.4g} Hz exchanged for a random-walk drift",
                        replace(fewer, drift=RandomWalk.kind),
                        rates,
                    )
                )
            if search["gain"] and not spec.gain:
                out.append(
                    move(
                        f"the line at {f:.4g} Hz exchanged for a gain drift",
                        replace(fewer, gain=GAIN_TERMS),
                        [{**start, **_gain_values(fit.model.gain_start(GAIN_TERMS))}],
                    )
                )
    if search["drift"] and spec.drifting:
        out.append(move("remove the drift", replace(spec, drift=NO_DRIFT), [dict(values)]))
    if search["noise"] and spec.coloured:
        out.append(move(f"remove the {spec.noise} noise", replace(spec, noise=NO_NOISE, white=True), [with_white]))
        current = NOISE_TERMS[spec.noise]()
        for other, noise in coloured_noises():  # each other coloured noise in its place
            if other != spec.noise:
                starts = noise.replacing(current, values, series.dt)
                out.append(move(f"{spec.noise} noise exchanged for {other} noise", replace(spec, noise=other), starts))
        if search.get("white") and spec.white:
            # AR(1) alone (the sensor's noise coloured) leaves sigma flat down to its prior's bound
            out.append(move("remove the white noise", replace(spec, white=False), [dict(values)]))
    if search["gain"] and spec.gain:
        out.append(move("remove the gain drift", replace(spec, gain=0), [dict(values)]))
        if search["drift"] and not spec.drifting:
            start = {**values, "drift.rate": 0.1 * sigma / math.sqrt(span)}
            out.append(
                move(
                    "the gain drift exchanged for a random-walk drift",
                    replace(spec, gain=0, drift=RandomWalk.kind),
                    [start],
                )
            )
    if search["gain"] and search["drift"] and not spec.gain and spec.drifting:
        start = {**values, **_gain_values(fit.model.gain_start(GAIN_TERMS))}
        out.append(
            move("the drift exchanged for a gain drift", replace(spec, gain=GAIN_TERMS, drift=NO_DRIFT), [start])
        )
    if search["noise"] and search["drift"]:
        if spec.coloured and not spec.drifting:
            rms = values[NOISE_TERMS[spec.noise].rms_name]
            start = {**with_white, "drift.rate": rms / math.sqrt(span)}
            out.append(
                move(
                    f"{spec.noise} noise exchanged for a random-walk drift",
                    replace(spec, noise=NO_NOISE, drift=RandomWalk.kind, white=True),
                    [start],
                )
            )
        if not spec.coloured and DRIFT_TERMS[spec.drift] is RandomWalk:
            # a slow AR(1) and a random walk describe much the same spectrum
            starts = [{**values, "ar.rms": values["drift.rate"] * math.sqrt(span), "ar.time": span / 10.0}]
            out.append(
                move("the drift exchanged for AR(1) noise", replace(spec, noise=AR1.kind, drift=NO_DRIFT), starts)
            )
    return out


@dataclass(frozen=True)
class SlowReading:
    """The modulation test of a slow line (`slow_reading`): the line's index, frequency and cycles
    in the record; `log_ratio`, ln L of the multiplicative reading minus ln L of the additive one
    (the line itself); `expected`, the mean |log ratio| when either reading is true (what the test
    can tell); and the verdict: "additive" (a line), "same" (nothing for a gain to modulate: the
    two readings are one description of the data, and the line, the shorter, stands),
    "multiplicative" or "undecided" (a slow variation of the level, not a detected line)."""

    line: int
    frequency: float
    cycles: float
    log_ratio: float
    expected: float
    verdict: str


def _shaped_gain(spec: ModalSpec, series: Series, shape: np.ndarray) -> ModalModel:
    """The modal model of `spec` (gain = 1) whose one gain basis function is `shape`: with
    `gain.a1` = 1 its multiplier is 1 + shape (`ModalModel.multiplier`)."""
    return ModalModel({"modal": spec.table()}, series, gain_shapes=shape[None, :])


def slow_reading(fit: OrderFit, series: Series, j: int, replicates: int = REPLICATES, seed: int = 0) -> SlowReading:
    """Line `j` of `fit`, a slow one, read two ways: additively (the line, as fitted) and as a
    gain: the same curve s(t) = A cos(2 pi f t + phase) made a factor 1 + s / level of the whole
    signal, the other lines and the modes included (the modal model's y = (1 + g)(level + ...),
    `vibinverse.models.modal`). Both readings have the same mean, level + s, and the same
    parameters; they differ only in whether the vibration's amplitude follows s. Their
    log-likelihood ratio at the fitted values is the evidence of that modulation, and its mean
    over `replicates` draws of each reading (`ModalModel.replicate`, seeded) what the data can
    tell. The verdict (`SlowReading`): "same" when the model has no other mode or line (nothing to
    modulate: the ratio is 0 whatever the data) or the level is not well above the data's sd (a
    gain of a level near 0 means nothing); else "additive" or "multiplicative" when the ratio
    decides at 19 : 1 (DECIDED, even prior odds), "undecided" otherwise."""
    spec, values, model = fit.spec, fit.values, fit.model
    f, a, ph = (values[f"lines[{j}].{k}"] for k in ("frequency", "amplitude", "phase"))
    level = values["level"]
    cycles = f * max(model.span, series.dt)
    base = model.multiplier(values).copy() if spec.gain else np.ones(model.t.size)
    shape = base * (1.0 + a * np.cos(2.0 * np.pi * f * model.t + ph) / level) - 1.0 if level else base - 1.0
    alone = spec.modes == 0 and spec.lines == 1
    if alone or not abs(level) > model.sd or not np.min(1.0 + shape) > 0.0:
        return SlowReading(j, f, cycles, 0.0, 0.0, "same")
    gain_spec = replace(spec, lines=spec.lines - 1, gain=1)
    gain_values = {n: v for n, v in renumber(values, "lines", j, spec.lines).items() if not n.startswith("gain.")}
    gain_values["gain.a1"] = 1.0
    gain_model = _shaped_gain(gain_spec, series, shape)
    ratio = gain_model.log_likelihood(gain_values) - fit.log_likelihood
    rng = np.random.default_rng(seed)
    diffs = []
    for _ in range(replicates):
        for src, v, sign in ((gain_model, gain_values, 1.0), (model, values, -1.0)):
            rep = replace(series, intensity=src.replicate(v, rng))
            lm = _shaped_gain(gain_spec, rep, shape).log_likelihood(gain_values)
            la = ModalModel({"modal": spec.table()}, rep).log_likelihood(values)
            diffs.append(sign * (lm - la))
    if ratio < -DECIDED:
        verdict = "additive"
    elif ratio > DECIDED:
        verdict = "multiplicative"
    else:
        verdict = "undecided"
    return SlowReading(j, f, cycles, float(ratio), float(np.mean(diffs)), verdict)


def slow_exchanges(fit: OrderFit, series: Series, j: int, search: dict[str, bool]) -> list[Candidate]:
    """Slow line `j` of `fit` as a nuisance term: a gain drift of GAIN_TERMS, +2 and +4 cosines
    (more than the fit's gain drift has; started on the least-squares fit of the cosines to the
    gain that line and gain drift make together), and a random-walk drift."""
    spec, values, model = fit.spec, fit.values, fit.model
    f, a, ph = (values[f"lines[{j}].{k}"] for k in ("frequency", "amplitude", "phase"))
    start = renumber(values, "lines", j, spec.lines)
    fewer = replace(spec, lines=spec.lines - 1)
    span = max(model.span, series.dt)
    out = []
    if search["gain"] and abs(values["level"]) > model.sd:
        base = model.multiplier(values).copy() if spec.gain else np.ones(model.t.size)
        target = base * (1.0 + a * np.cos(2.0 * np.pi * f * model.t + ph) / values["level"])
        for terms in sorted({min(24, max(GAIN_TERMS, spec.gain + 2) + d) for d in (0, 2, 4)}):
            basis = gain_basis(model.t, terms)[:, model.good]
            design = np.vstack([np.ones(basis.shape[1]), basis]).T
            d = np.linalg.lstsq(design, target[model.good], rcond=None)[0]
            st = {n: v for n, v in start.items() if not n.startswith("gain.")}
            st = {**st, "level": values["level"] * d[0], **_gain_values(d[1:] / d[0])}
            out.append(Candidate(f"a gain drift of {terms} cosines", replace(fewer, gain=terms), [st], []))
    if search["drift"] and not spec.drifting:
        rates = [{**start, "drift.rate": a / math.sqrt(span) * k} for k in (0.3, 1.0)]
        out.append(Candidate("a random-walk drift", replace(fewer, drift=RandomWalk.kind), rates, []))
    return out


def settle_slow(
    series: Series, current: OrderFit, search: dict[str, bool], rows: list[dict[str, Any]], step: int
) -> OrderFit | None:
    """The chosen order's lines of under FEW_CYCLES cycles, lowest first, each read additively and
    as a gain (`slow_reading`): the first one the data do not decide to be a line (verdict
    "multiplicative" or "undecided": a slow variation, not a detected line) exchanged for the best
    (by BIC) of its nuisance descriptions (`slow_exchanges`); None when every slow line stands.
    Each reading is a row of the criterion table."""
    if not search["lines"]:
        return None
    span = max(current.model.span, series.dt)
    order = sorted(range(current.spec.lines), key=lambda j: current.values[f"lines[{j}].frequency"])
    for j in order:
        if current.values[f"lines[{j}].frequency"] * span >= FEW_CYCLES:
            continue
        r = slow_reading(current, series, j)
        what = (
            f"the line at {r.frequency:.4g} Hz ({r.cycles:.1f} cycles) read as a gain: {r.verdict} "
            f"(ln L ratio {r.log_ratio:+.1f}, expected {r.expected:.1f})"
        )
        exchanges = slow_exchanges(current, series, j, search) if r.verdict in ("multiplicative", "undecided") else []
        fits = [(c, fit_order(series, c.spec, c.starts, windows=current.windows)) for c in exchanges]
        if not fits:
            rows.append(_row(step, what + ": the line stands", current, current.bic, "modulation test", False))
            continue
        c, best = min(fits, key=lambda cf: cf[1].bic)
        rows.append(_row(step, f"{what}: exchanged for {c.what}", best, current.bic, "full", True))
        logger.info("model order: %s: exchanged for %s, BIC %.1f -> %.1f", what, c.what, current.bic, best.bic)
        return best
    return None


def swapped(
    fit: OrderFit, series: Series, search: dict[str, bool], caps: tuple[int, int] = (MAX_MODES, MAX_LINES)
) -> list[tuple[Candidate, float, bool]]:
    """Each line read as a resonance at its frequency, and each narrow resonance (half-power
    bandwidth 2 zeta f within SWAP_BINS Fourier bins) read as a line, as (candidate, frequency,
    whether the candidate is the resonance reading): a lightly damped resonance is as steady as a
    line over a short record, and the forward step keeps whichever of the two its spectral start
    fits better first."""
    spec, values = fit.spec, fit.values
    span = max(fit.model.span, series.dt)
    out: list[tuple[Candidate, float, bool]] = []
    if not (search["modes"] and search["lines"]):
        return out
    for j in range(spec.lines):
        f, a = values[f"lines[{j}].frequency"], values[f"lines[{j}].amplitude"]
        if f * span < FEW_CYCLES or spec.modes >= caps[0]:
            continue  # a slow line is read as a drift or a gain (`settle_slow`), not as a resonance
        k = spec.modes
        start = renumber(values, "lines", j, spec.lines)
        mode = {f"modes[{k}].frequency": f, f"modes[{k}].rms": a / math.sqrt(2.0)}
        starts = [{**start, **mode, f"modes[{k}].damping_ratio": b / (2.0 * f * span)} for b in (0.5, 3.0)]
        what = f"the line at {f:.6g} Hz read as a resonance"
        new = [f"modes[{k}].{p}" for p in ("frequency", "damping_ratio", "rms")]
        out.append((Candidate(what, replace(spec, lines=spec.lines - 1, modes=k + 1), starts, new), f, True))
    for i in range(spec.modes):
        f, z, rms = (values[f"modes[{i}].{p}"] for p in ("frequency", "damping_ratio", "rms"))
        if bandwidth_bins(fit, f) > SWAP_BINS or f * span < FEW_CYCLES or spec.lines >= caps[1]:
            continue
        k = spec.lines
        start = renumber(values, "modes", i, spec.modes)
        line = {f"lines[{k}].frequency": f, f"lines[{k}].amplitude": rms * math.sqrt(2.0)}
        starts = [{**start, **line, f"lines[{k}].phase": ph} for ph in (-2.0, 0.0, 2.0)]
        what = f"the resonance at {f:.5g} Hz (zeta {z:.2g}) read as a line"
        new = [f"lines[{k}].{p}" for p in ("frequency", "amplitude", "phase")]
        out.append((Candidate(what, replace(spec, modes=spec.modes - 1, lines=k + 1), starts, new), f, False))
    return out


def bandwidth_bins(fit: OrderFit, f: float) -> float:
    """The half-power bandwidth 2 zeta f of `fit`'s mode nearest f, in Fourier bins (1 / span)."""
    spec, values = fit.spec, fit.values
    i = min(range(spec.modes), key=lambda i: abs(values[f"modes[{i}].frequency"] - f))
    z, fi = values[f"modes[{i}].damping_ratio"], values[f"modes[{i}].frequency"]
    return 2.0 * z * fi * max(fit.model.span, fit.model.dt)


def settle_swaps(
    series: Series,
    current: OrderFit,
    search: dict[str, bool],
    rows: list[dict[str, Any]],
    step: int,
    caps: tuple[int, int] = (MAX_MODES, MAX_LINES),
    workers: int = 1,
) -> tuple[OrderFit | None, list[dict[str, Any]]]:
    """Each line and narrow resonance of the chosen order read as the other kind (`swapped`), fitted
    with only the new component, the level, the white noise and the modes near it free, and
    refitted in full when it may lower the BIC (within 0.5 ln n, as in `_best_move`) or be a
    resolved reading within the margin: (the best reading when it lowers the BIC, else None; the
    readings the data cannot rule out, as `diagnostics["ambiguous"]` entries). A reading is
    ambiguous when it is less than DECIDED (ln 19, the two-readings test of `slow_reading`: both
    have the same parameters and frequency, so no look-elsewhere term enters) below the chosen one
    in ln L and its resonance is resolved (bandwidth of a Fourier bin or more): a resonance
    narrower than that is, over the record, the same steady oscillation as a line, and its damping
    ratio's interval already says how little is known. Each reading is a row of the criterion
    table. After a reading is taken the search goes on, and the next call reads every component
    again (the unchanged ones too: one partial fit each). The readings are independent: `workers`
    threads fit them (the same numbers as one)."""
    slack = 0.5 * math.log(current.n)

    def read(swap: tuple[Candidate, float, bool]) -> tuple[Candidate, OrderFit, float, bool]:
        c, f, as_mode = swap
        keep = [*c.new, "level", "noise.sigma", *near_modes(c, current.model.span)]
        alt = fit_order(series, c.spec, c.starts, free=keep, maxiter=60, ftol=1e-9, windows=current.windows)
        bins = bandwidth_bins(alt if as_mode else current, f)
        # refitted in full only when it may win, or be a resolved reading within the margin
        full = alt.bic < current.bic + slack or (
            current.log_likelihood - alt.log_likelihood < DECIDED + slack and bins >= 0.5
        )
        if full:
            alt = fit_order(series, c.spec, [alt.values], windows=current.windows)
            bins = bandwidth_bins(alt if as_mode else current, f)
        return c, alt, bins, full

    readings = thread_map(read, swapped(current, series, search, caps), workers)
    for c, alt, _, full in readings:
        rows.append(_row(step, c.what, alt, current.bic, "full" if full else "partial", False))
    if not readings:
        return None, []
    i = min(range(len(readings)), key=lambda i: readings[i][1].bic)
    c, best, _, full = readings[i]
    if full and best.bic < current.bic:
        rows[i - len(readings)]["kept"] = True
        logger.info("model order: %s, BIC %.1f -> %.1f", c.what, current.bic, best.bic)
        return best, []
    ambiguous = []
    for c, alt, bins, full in readings:
        gap = current.log_likelihood - alt.log_likelihood
        if full and gap < DECIDED and bins >= 1.0:
            values = {n: v for n, v in alt.values.items() if n.endswith((".frequency", ".damping_ratio"))}
            ambiguous.append(
                {
                    "alternative": c.what,
                    "delta_log_posterior": float(gap),
                    "measure": "log likelihood",
                    "decided_at": f"19 : 1, {DECIDED:.1f}, would decide",
                    "values": values,
                    "advice": "Whether this is a resonance or a steady line is not decided by these data: "
                    "a longer record decides (a resonance's phase wanders over its decay time, a line's does not).",
                }
            )
    return None, ambiguous


def onset_profile(
    series: Series, spec: ModalSpec, values_at: Callable[[int], dict[str, float]], samples: Iterable[int]
) -> tuple[float, int, dict[str, float]]:
    """(ln L, sample, values) at the best of the decays' onsets at `samples` (each the order `spec`
    with its onset there, at the values `values_at(sample)`)."""
    best: tuple[float, int, dict[str, float]] = (-math.inf, 0, {})
    t = series.time
    for i in samples:
        values = values_at(i)
        model = ModalModel({"modal": {**replace(spec, onset=float(t[i] - t[0])).table(), "start": values}}, series)
        ll = model.log_likelihood(values)
        if ll > best[0]:
            best = (ll, i, values)
    return best


def fine_samples(i: int, n: int) -> range:
    """The samples within ONSET_STEP of the record around sample i."""
    step = max(1, int(ONSET_STEP * n))
    return range(max(0, i - step), min(n - 1, i + step + 1))


def set_onset(series: Series, fit: OrderFit) -> OrderFit:
    """`fit` with its decays' onset where the likelihood at its values is highest (`onset_profile`:
    the record's start, every ONSET_STEP of the record over its first ONSET_REACH, then every sample
    around the best), refitted there when that is not where it was."""
    n = fit.model.t.size
    at = fit.model.onset
    step = max(1, int(ONSET_STEP * n))
    hold = lambda i: fit.values  # the same values at every onset
    _, best, _ = onset_profile(series, fit.spec, hold, sorted({0, at, *range(0, int(ONSET_REACH * n), step)}))
    if best > 0:
        _, best, _ = onset_profile(series, fit.spec, hold, [0, at, *fine_samples(best, n)])
    here = replace(fit, spec=replace(fit.spec, onset=float(series.time[at] - series.time[0])))
    if best == at:
        return here
    moved = fit_order(series, replace(fit.spec, onset=float(series.time[best] - series.time[0])), [fit.values])
    return moved if moved.log_likelihood > fit.log_likelihood else here


def decay_readings(fit: OrderFit, series: Series, search: dict[str, bool]) -> list[Candidate]:
    """Each mode (when modes are searched) and each line (when lines are) of at least FEW_CYCLES
    cycles whose band's envelope falls over the ring (`envelope_decay`, from the data's blow, or the
    record's start: zeta 2 pi f ring at least DECAY_ENVELOPE_FALL) read as a free decay at its
    frequency, started from its own damping (a mode's) and from the envelope's, its onset where the
    likelihood at that start is highest (`onset_profile`: the record's start, every ONSET_STEP of
    the record over its first ONSET_REACH, then every sample around the best). Not on a record of
    WHITTLE_MIN_SAMPLES or more: a decay runs on the filter's engine only, minutes a reading there
    (the beam's 63,000 samples with six modes: over a minute), and a record that long is rarely
    one ring."""
    spec, values, model = fit.spec, fit.values, fit.model
    if not search.get("decays", True):
        return []
    if model.n_obs >= WHITTLE_MIN_SAMPLES:
        logger.info("model order: free decays are not read on a record this long (the filter's engine only)")
        return []
    if series.passband is not None:
        logger.info(
            "model order: free decays are not read below an anti-alias roll-off (the filter's engine only, "
            "and it sees the whole band)"
        )
        return []
    onset = excitation_onset(model.t, model.y)
    ring = float(model.t[-1] - model.t[onset])
    span = max(model.span, series.dt)
    n = model.t.size
    out: list[Candidate] = []
    if ring <= 0:
        return out
    k = spec.decays
    new = [f"decays[{k}].{p}" for p in ("frequency", "damping_ratio", "amplitude")]
    parts = []
    if search["modes"]:
        for i in range(spec.modes):
            f, z, rms = (values[f"modes[{i}].{p}"] for p in ("frequency", "damping_ratio", "rms"))
            parts.append(("modes", i, spec.modes, f, z, rms, f"the resonance at {f:.5g} Hz read as a free decay"))
    if search["lines"]:
        for j in range(spec.lines):
            f, a = values[f"lines[{j}].frequency"], values[f"lines[{j}].amplitude"]
            what = f"the line at {f:.6g} Hz read as a free decay"
            parts.append(("lines", j, spec.lines, f, None, abs(a) / math.sqrt(2.0), what))
    for kind, i, count, f, z, rms, what in parts:
        if f * ring < FEW_CYCLES:
            continue
        half = max(3.0 / ring, 3.0 * (z or 0.0) * f)
        fall = envelope_decay(model.y[onset:], series.dt, f, half)
        if fall * 2.0 * math.pi * f * ring < DECAY_ENVELOPE_FALL:
            continue
        start = renumber(values, kind, i, count)
        zetas = sorted({min(max(x, 1e-5), 0.5) for x in (fall, z) if x})
        fewer = replace(spec, **{kind: count - 1, "decays": k + 1})

        def at(sample: int, zeta: float = zetas[0]) -> dict[str, float]:
            left = float(series.time[-1] - series.time[sample])
            return {**start, **ring_start(f"decays[{k}]", f, zeta, rms, left, span)}

        step = max(1, int(ONSET_STEP * n))
        _, best, _ = onset_profile(series, fewer, at, range(0, int(ONSET_REACH * n), step))
        if best > 0:
            _, best, _ = onset_profile(series, fewer, at, [0, *fine_samples(best, n)])
        fewer = replace(fewer, onset=float(series.time[best] - series.time[0]))
        out.append(Candidate(what, fewer, [at(best, x) for x in zetas], new))
    return out


def settle_decays(
    series: Series,
    current: OrderFit,
    search: dict[str, bool],
    rows: list[dict[str, Any]],
    step: int,
    workers: int = 1,
) -> OrderFit | None:
    """Each mode and line whose band decays over the record read as a free decay (`decay_readings`),
    fitted with only the decay, the level, the white noise and the modes near it free; those that
    may win (within 0.5 ln n of the BIC), best first, refitted in full, their onset then set again
    where the likelihood at the fit is highest (`set_onset`, refitted when it moves). A reading is
    taken when it raises ln L by DECIDED (ln 19) or more (the same parameters and frequency: no
    look-elsewhere term; a ring and a steady or noise-driven oscillation are both read at 19 : 1
    before either is claimed), plus 0.5 ln n (a parameter's BIC price) when its onset lies inside
    the record; the next is then read again from the fit that took it (its candidate nearest in
    frequency), without the whole search in between: a plucked string's five partials, one after
    the other. Returns the last fit taken, or None. Each reading is a row of the criterion table.
    The partial fits run on `workers` threads (the same numbers as one)."""
    slack = 0.5 * math.log(current.n)
    price = lambda a: DECIDED + (slack if a.spec.onset else 0.0)
    frequency = lambda c: c.starts[0][c.new[0]]
    cands = decay_readings(current, series, search)
    partial = list(zip(cands, thread_map(lambda c: partial_fit(series, current, c), cands, workers)))
    partial.sort(key=lambda cp: cp[1].log_likelihood - price(cp[1]), reverse=True)
    for c, pf in partial:
        rows.append(_row(step, c.what, pf, current.bic, "partial", False))
    queue = [frequency(c) for c, pf in partial if pf.bic < current.bic + slack]
    taken: OrderFit | None = None
    for f in queue:
        if taken is None:
            c = next((c for c, _ in partial if frequency(c) == f), None)
        else:  # the same component in the fit that took the last reading
            cands = decay_readings(current, series, search)
            near = [c for c in cands if abs(frequency(c) - f) <= 1.0 / max(current.model.span, series.dt)]
            c = min(near, key=lambda c: abs(frequency(c) - f), default=None)
        if c is None:
            continue
        start = next((pf.values for cc, pf in partial if cc is c), c.starts[0])
        alt = set_onset(series, fit_order(series, c.spec, [start], windows=current.windows))
        won = alt.log_likelihood >= current.log_likelihood + price(alt)
        rows.append(_row(step, c.what, alt, current.bic, "full", won))
        if won:
            logger.info("model order: %s, BIC %.1f -> %.1f", c.what, current.bic, alt.bic)
            current = taken = alt
    return taken


def near_line_candidates(fit: OrderFit, series: Series) -> list[tuple[Candidate, int, tuple[float, float]]]:
    """For each resonance, a line at the residual spectrum's strongest peak within its `near_band`,
    at least a Fourier bin from it and from every line, as (candidate with the mode's parameters free, the
    mode's index, the band searched there (lo, hi) Hz); a peak next to two modes once."""
    from vibinverse.spectrum import sinusoid, strongest_sinusoid

    spec, values, model = fit.spec, fit.values, fit.model
    dt = float(model.steps[0]) if model.steps.size == 1 else series.dt
    span, nyq = max(model.span, dt), min(0.5 / dt, series.top)
    freqs, power = spectrum(model.residuals(values), dt, model.t)
    taken = [values[f"lines[{j}].frequency"] for j in range(spec.lines)]
    y0 = model.y - model.mean(values)
    df = freqs[1] - freqs[0]
    out, peaks = [], []
    for i in range(spec.modes):
        f, z = values[f"modes[{i}].frequency"], values[f"modes[{i}].damping_ratio"]
        window = near_band(f, z, span, nyq)
        band = (freqs >= window[0]) & (freqs <= window[1]) & (np.abs(freqs - f) >= 1.0 / span)
        band &= freqs < 0.999 * nyq
        for g in taken:
            band &= np.abs(freqs - g) >= 1.0 / span
        if not band.any():
            continue
        c = freqs[np.flatnonzero(band)[np.argmax(power[band])]]
        if any(abs(c - done) < 0.5 * df for done in peaks):
            continue  # the same peak next to two modes: tried once, next to the first
        peaks.append(float(c))
        g = strongest_sinusoid(model.t, y0, np.linspace(c - df, c + df, 41))
        a, ph, _ = sinusoid(model.t, y0, g)
        k = spec.lines
        new = [f"lines[{k}].frequency", f"lines[{k}].amplitude", f"lines[{k}].phase"]
        mode = [f"modes[{i}].frequency", f"modes[{i}].damping_ratio", f"modes[{i}].rms"]
        what = f"a line at {g:.5g} Hz next to the resonance at {f:.5g} Hz"
        start = {**values, new[0]: g, new[1]: a, new[2]: ph}
        out.append((Candidate(what, replace(spec, lines=k + 1), [start], [*new, *mode]), i, window))
    return out


def new_line(alt: OrderFit, before: OrderFit) -> int:
    """The index in `alt` of the line `before` does not have (`sort_labels` renumbers lines by
    frequency, so the added line need not be the last)."""
    old = [before.values[f"lines[{j}].frequency"] for j in range(before.spec.lines)]
    freqs = [alt.values[f"lines[{j}].frequency"] for j in range(alt.spec.lines)]
    return max(range(len(freqs)), key=lambda j: min((abs(freqs[j] - g) for g in old), default=math.inf))


def in_core(alt: OrderFit, before: OrderFit, mode: int, line: int) -> bool:
    """Whether `alt`'s line `line` lies within CORE_HALF_WIDTHS half-power half-widths (zeta f) of
    resonance `mode` as fitted without it (`before`): there it does not sit beside the resonance's
    peak but takes its place."""
    f, z = before.values[f"modes[{mode}].frequency"], before.values[f"modes[{mode}].damping_ratio"]
    return abs(alt.values[f"lines[{line}].frequency"] - f) <= CORE_HALF_WIDTHS * z * f


def settle_near_lines(
    series: Series,
    current: OrderFit,
    search: dict[str, bool],
    rows: list[dict[str, Any]],
    step: int,
    caps: tuple[int, int] = (MAX_MODES, MAX_LINES),
    workers: int = 1,
) -> tuple[OrderFit | None, bool, list[tuple[dict[str, Any], OrderFit]]]:
    """A weak line next to a resonance (`near_line_candidates`): the forward step proposes a line at
    the strongest residual peak of the whole band, and a resonance that took in a weak line's power
    widens and moves towards it, which hides the peak. Each near line is fitted with the mode free
    (partial, then in full when it may pass). Returns (the order to go on from, or None; whether
    that order is final; ambiguous readings as (`diagnostics["ambiguous"]` entry, that reading's
    fit)):
    - a line that lowers the BIC is kept, and the search goes on from it;
    - else the best (by BIC) line off its mode's core (`in_core`) that gains KEEP_GAIN + ln M_near
      in ln L (M_near the frequencies searched next to the mode) is kept for the
      resonance's estimate, not claimed (its detection test asks 12.5 + ln M_near), and that order
      is final (a backward move by the BIC would take it out again); the reading without it is
      reported as ambiguous (the resonance's values it implies);
    - the other possible lines (gaining POSSIBLE_GAIN + ln M_near) are reported as ambiguous
      readings with the resonance's values they imply."""
    if not search["lines"] or current.spec.lines >= caps[1] or not current.spec.modes:
        return None, False, []
    slack = 0.5 * math.log(current.n)

    def near(cand: tuple[Candidate, int, tuple[float, float]]) -> tuple[Candidate, int, float, OrderFit, bool]:
        c, i, (lo, hi) = cand
        ln_m = math.log(band_frequencies((lo, hi), current.model.span))
        windows = (*current.windows, (lo, hi))
        free = [*c.new, "level", "noise.sigma"]
        alt = fit_order(series, c.spec, c.starts, free=free, maxiter=60, ftol=1e-9, windows=windows)
        full = alt.log_likelihood - current.log_likelihood >= POSSIBLE_GAIN + ln_m - slack
        if full:
            alt = fit_order(series, c.spec, [alt.values], windows=windows)
        return c, i, ln_m, alt, full

    found = thread_map(near, near_line_candidates(current, series), workers)  # independent: the same numbers
    for c, _, _, alt, full in found:
        rows.append(_row(step, c.what, alt, current.bic, "full" if full else "partial", False))
    if not found:
        return None, False, []
    best = min(found, key=lambda x: x[3].bic)
    if best[4] and best[3].bic < current.bic:
        rows[found.index(best) - len(found)]["kept"] = True
        logger.info("model order: %s, BIC %.1f -> %.1f", best[0].what, current.bic, best[3].bic)
        return best[3], False, []

    def gained(x: tuple) -> float:
        return x[3].log_likelihood - current.log_likelihood

    possible = [x for x in found if x[4] and gained(x) >= POSSIBLE_GAIN + x[2]]
    beside = [x for x in possible if gained(x) >= KEEP_GAIN + x[2]]
    beside = [x for x in beside if not in_core(x[3], current, x[1], new_line(x[3], current))]
    kept = min(beside, key=lambda x: x[3].bic) if beside else None
    ambiguous = []
    for x in possible:
        c, i, ln_m, alt, _ = x
        k = new_line(alt, current)
        names = [f"modes[{i}].frequency", f"modes[{i}].damping_ratio", f"lines[{k}].frequency", f"lines[{k}].amplitude"]
        said = (
            f"the line gains {gained(x):.1f} in ln L, {POSSIBLE_GAIN + ln_m:.1f} would make it possible, "
            f"{KEEP_GAIN + ln_m:.1f} keep it for the resonance's estimate, "
            f"{0.5 * (alt.bic - current.bic) + gained(x):.1f} detect it"
        )
        decides = "A longer record, or the drive's frequency from elsewhere (fixed in modal.values), decides."
        f, z = names[0], names[1]
        if kept is not None and c is kept[0]:
            row = rows[found.index(kept) - len(found)]
            row["kept"], row["fit"] = True, f"{row['fit']}; kept as a possible line, not detected"
            logger.info("model order: %s kept for the resonance's estimate (a possible line, not detected)", c.what)
            entry = {
                "alternative": f"no line next to the resonance at {current.values[f]:.5g} Hz",
                "delta_log_posterior": float(gained(x)),
                "measure": "ln L",
                "values": {n: float(current.values[n]) for n in (f, z)},
                "intervals_of": "Without the line",
                "advice": f"Resonance {i}'s values depend on whether a line at {alt.values[names[2]]:.5g} Hz is "
                f"there: the fit keeps it (a resonance that takes in a line's power moves towards it), giving "
                f"{alt.values[f]:.5g} Hz (zeta {alt.values[z]:.2g}); without it {current.values[f]:.5g} Hz "
                f"(zeta {current.values[z]:.2g}). {decides}",
            }
            ambiguous.append(({**entry, "decided_at": said, "mode": i}, current))
            continue
        base = kept[3] if kept is not None else current
        entry = {
            "alternative": c.what,
            "delta_log_posterior": float(0.5 * (alt.bic - current.bic)),
            "measure": "BIC / 2 (with the look-elsewhere term)",
            "values": {n: float(alt.values[n]) for n in names},
            "advice": f"Resonance {i}'s values depend on whether this line is there: with it, "
            f"{alt.values[f]:.5g} Hz (zeta {alt.values[z]:.2g}) instead of "
            f"{base.values[f]:.5g} Hz (zeta {base.values[z]:.2g}). {decides}",
        }
        ambiguous.append(({**entry, "decided_at": said, "mode": i}, alt))
    return (kept[3] if kept is not None else None), kept is not None, ambiguous


def choose_order(
    series: Series,
    table: dict[str, Any] | None = None,
    *,
    max_modes: int = MAX_MODES,
    max_lines: int = MAX_LINES,
    max_steps: int = 20,
    workers: int = 1,
) -> OrderResult:
    """Choose the modal model's order for `series` by stepwise BIC selection (module docstring).
    `table`: a `{"modal": {...}}` table whose `modes`, `lines`, `drift`, `noise` are fixed (not
    searched); None searches all. `workers`: threads for each step's candidates (`_best_move`).
    Returns the chosen fit and the criterion table."""
    t0 = time.perf_counter()
    fixed = dict((table or {}).get("modal") or {})
    spec = ModalSpec.from_table({"modal": {k: fixed[k] for k in (*SEARCHED, "white", "decays", "onset") if k in fixed}})
    search = {k: k not in fixed for k in SEARCHED}
    search["decays"] = "decays" not in fixed  # read from the modes and lines (`settle_decays`)
    search["white"] = search["noise"] and "white" not in fixed
    current = fit_fixed(series, spec)
    if search["gain"] and current.model.spectral is not None:
        # a gain drift's likelihood needs the Kalman filter: minutes per fit on a record this long
        search["gain"] = False
        logger.info("model order: a gain drift is not searched on a long record (give `gain` to fit one)")
    rows: list[dict[str, Any]] = [_row(0, "start: " + _describe(spec), current, None, "full", True)]
    logger.info("model order: %s, BIC %.1f", _describe(spec), current.bic)
    ambiguous: list[dict[str, Any]] = []
    readings: dict[str, OrderFit] = {}
    lowest = MIN_CYCLES  # after a slow line was read as a slow variation, none is proposed again
    step = 1
    while step <= max_steps:
        cands = candidates(current, series, search, (max_modes, max_lines), lowest)
        best = _best_move(series, current, cands, rows, step, workers)
        if best is None:  # nothing to add: remove or exchange a component
            best = _best_move(series, current, neighbours(current, series, search), rows, step, workers)
        if best is None:  # nothing lowers the BIC: does each slow line stand as a line?
            best = settle_slow(series, current, search, rows, step)
            lowest = FEW_CYCLES
        if best is None:  # ... and is each line not a resonance, each narrow resonance not a line?
            best, ambiguous = settle_swaps(series, current, search, rows, step, (max_modes, max_lines), workers)
        if best is None:  # ... and does none of them ring down from one excitation?
            best = settle_decays(series, current, search, rows, step, workers)
        final = False
        if best is None:  # ... and has no resonance taken in a weak line next to it?
            best, final, near = settle_near_lines(series, current, search, rows, step, (max_modes, max_lines), workers)
            ambiguous = [] if best is not None and not final else [*ambiguous, *(e for e, _ in near)]
            readings = {e["alternative"]: f for e, f in near}
        if best is None:
            break
        current = best
        if final:
            break
        step += 1
    capped = beyond_caps(series, current, search, (max_modes, max_lines), lowest)
    for entry in capped:
        logger.warning(
            "model order: the search stopped at its cap of %d %s, and one more (%s) lowers the BIC by %.0f: the "
            "record holds more than the fit describes (give `%s` in the `modal` table to fit more)",
            entry["cap"],
            entry["kind"],
            entry["what"],
            -entry["delta_bic"],
            entry["kind"],
        )
    return OrderResult(current, rows, time.perf_counter() - t0, ambiguous, readings, capped)


def beyond_caps(
    series: Series, fit: OrderFit, search: dict[str, bool], caps: tuple[int, int], cycles: float = MIN_CYCLES
) -> list[dict[str, Any]]:
    """For each kind (modes, lines) searched and at its cap in `fit`: the candidate of that kind the
    forward step would propose next (`candidates`, the cap raised by one), fitted with its own
    parameters free (`partial_fit`: a lower bound of its gain); an entry {"kind", "cap", "what",
    "delta_bic"} when that already lowers the BIC. The caps bound the search's time, not what
    the record holds (the LIGO strain's violin modes fill the 6 lines)."""
    out: list[dict[str, Any]] = []
    counts = (fit.spec.modes, fit.spec.lines)
    for i, kind in enumerate(("modes", "lines")):
        if not search[kind] or counts[i] < caps[i]:
            continue
        raised = (caps[0] + (i == 0), caps[1] + (i == 1))
        for c in candidates(fit, series, {**dict.fromkeys(search, False), kind: True}, raised, cycles):
            try:
                pf = partial_fit(series, fit, c)
            except NumericalError:
                continue
            if pf.bic < fit.bic:
                out.append({"kind": kind, "cap": caps[i], "what": c.what, "delta_bic": float(pf.bic - fit.bic)})
                break
    return out


def fit_fixed(series: Series, spec: ModalSpec) -> OrderFit:
    """`spec` fitted by maximum likelihood from the better (in ln L) of two starts: the spectral
    starts of the whole order (`ModalModel.guesses`: the strongest peaks of the data's spectrum),
    and, when it has both modes and lines, the order built up as the forward search builds it
    (`built_up`). With the counts given by the user the search adds nothing, and the spectral
    starts alone missed a weak line next to a resonance: with AR(1) noise the bench's weak_drive
    case put the line on the resonance's peak (or at 25-47 Hz) and the damping ratio 3x too high,
    14 below the true reading in ln L. Decays without an onset get the likeliest (`set_onset`)."""
    model = ModalModel({"modal": spec.table()}, series)
    direct = fit_order(series, spec, model.guesses(model.default_priors()))
    if spec.decays and spec.onset is None:  # the data's onset, and the likeliest at the spectral starts
        guess = model.guesses(model.default_priors())[0]
        n, step = model.t.size, max(1, int(ONSET_STEP * model.t.size))
        _, best, _ = onset_profile(series, spec, lambda i: guess, range(0, int(ONSET_REACH * n), step))
        if best > 0:
            _, best, _ = onset_profile(series, spec, lambda i: guess, [0, *fine_samples(best, n)])
        if best != model.onset:
            moved = replace(spec, onset=float(series.time[best] - series.time[0]))
            other = fit_order(series, moved, [guess])
            direct = other if other.log_likelihood > direct.log_likelihood else direct
        direct = set_onset(series, direct)
    if not (spec.modes and spec.lines):  # one kind only: no line to hide next to a resonance
        return direct
    built = built_up(series, spec)
    if built is not None and built.log_likelihood > direct.log_likelihood:
        logger.info(
            "model order: %s built up component by component, ln L %.1f (spectral starts %.1f)",
            _describe(spec),
            built.log_likelihood,
            direct.log_likelihood,
        )
        return built
    return direct


def built_up(series: Series, spec: ModalSpec) -> OrderFit | None:
    """`spec`'s modes and lines added one at a time to its nuisance terms, as the forward search
    adds them (`candidates`: a mode and a line at the strongest residual peak, a split of a broad
    mode; `near_line_candidates`: a line next to each resonance), each step taking the candidate of
    the highest ln L after a partial fit (the counts are given: no criterion decides), refitted in
    full. None when a step has no candidate."""
    bare = replace(spec, modes=0, lines=0)
    model = ModalModel({"modal": bare.table()}, series)
    current = fit_order(series, bare, model.guesses(model.default_priors()))
    while current.spec.modes < spec.modes or current.spec.lines < spec.lines:
        search = dict.fromkeys(SEARCHED, False)
        search["modes"] = current.spec.modes < spec.modes
        search["lines"] = current.spec.lines < spec.lines
        cands = candidates(current, series, search, (spec.modes, spec.lines))
        if search["lines"]:
            cands += [c for c, _, _ in near_line_candidates(current, series)]
        partial = [(c, partial_fit(series, current, c)) for c in cands]
        if not partial:
            return None
        c, pf = max(partial, key=lambda cp: cp[1].log_likelihood)
        current = fit_order(series, c.spec, [pf.values])
    return current


def near_modes(c: Candidate, span: float) -> list[str]:
    """The parameters of the candidate's modes (not new) whose band reaches a new frequency: within
    NEAR_BANDWIDTHS half-power bandwidths (2 zeta f) plus NEAR_BINS Fourier bins (1 / span). Freed
    in the partial fit: a mode fitted over two close peaks (a resonance and a line next to it) is
    broad and off-centre, and holding it fixed leaves the new component too little of the second
    peak to be refitted in full (the bench's near_drive case: a 4 Hz line next to 3.46 Hz was found
    in 26 of 50 data sets whose oracle decides it in 50)."""
    if not c.starts:
        return []
    start = c.starts[0]
    new_f = [start[n] for n in c.new if n.endswith(".frequency")]
    out: list[str] = []
    for i in range(c.spec.modes):
        name = f"modes[{i}].frequency"
        if name in c.new or name not in start:
            continue
        f, z = start[name], start[f"modes[{i}].damping_ratio"]
        if any(abs(g - f) <= near_reach(f, z, span) for g in new_f):
            out += [name, f"modes[{i}].damping_ratio", f"modes[{i}].rms"]
    return out


def partial_fit(series: Series, current: OrderFit, c: Candidate) -> OrderFit:
    """A candidate fitted with only its new parameters, the level, the white noise and the modes
    whose band reaches it (`near_modes`) free, the rest held at the current optimum (a few
    iterations: a cheap lower bound on its gain)."""
    keep = [*c.new, "level", "noise.sigma", *near_modes(c, current.model.span)]
    # a move of a mode or a line leaves a drift's rate where the filter set it (`drift_by_filter`)
    same = replace(c.spec, modes=0, lines=0) == replace(current.spec, modes=0, lines=0)
    return fit_order(
        series,
        c.spec,
        c.starts,
        free=keep,
        maxiter=60,
        ftol=1e-9,
        windows=current.windows,
        drift_set=same and current.spec.drifting,
    )


def _best_move(
    series: Series,
    current: OrderFit,
    cands: list[Candidate],
    rows: list[dict[str, Any]],
    step: int,
    workers: int = 1,
) -> OrderFit | None:
    """The best of the candidate orders (partial fits, then full refits of the best REFIT_TOP),
    when it lowers the BIC; every candidate recorded in `rows`. The candidates' screens, partial
    fits and refits are independent: `workers` threads run them (`vibinverse.parallel`), the same
    numbers as one."""
    if not cands:
        return None

    def screened(c: Candidate) -> tuple[Candidate, float | None]:
        # a nuisance term's grid: screened first
        return screen(series, current, c) if len(c.starts) > 2 else (c, None)

    kept_cands = []
    for c, gain in thread_map(screened, cands, workers):
        if gain is not None and not gain > 0:
            f = OrderFit(
                c.spec,
                current.model,
                c.starts[0],
                current.log_likelihood + gain,
                current.k + len(c.new),
                current.n,
                current.windows,
            )
            rows.append(_row(step, c.what, f, current.bic, "screened out (no gain on its grid of starts)", False))
            continue
        kept_cands.append(c)
    fits = thread_map(lambda c: partial_fit(series, current, c), kept_cands, workers)
    partial = sorted(zip(kept_cands, fits), key=lambda cp: cp[1].bic)
    slack = 0.5 * math.log(current.n)  # a partial fit this close to a lower BIC may get there refitted
    near = [(c, pf) for c, pf in partial[:REFIT_TOP] if pf.bic < current.bic + slack]
    # the partial fit's drift rate is the filter's (`drift_by_filter`), or the current's, set so too
    refit = lambda cp: fit_order(series, cp[0].spec, [cp[1].values], windows=current.windows, drift_set=True)
    refits = list(zip((c for c, _ in near), thread_map(refit, near, workers)))
    best = min(refits, key=lambda cf: cf[1].bic, default=None)
    kept = best is not None and best[1].bic < current.bic
    refitted = {id(c): f for c, f in refits}
    for c, pf in partial:
        f = refitted.get(id(c), pf)
        rows.append(
            _row(step, c.what, f, current.bic, "full" if id(c) in refitted else "partial", kept and c is best[0])
        )
    if not kept:
        return None
    logger.info("model order: + %s, BIC %.1f -> %.1f", best[0].what, current.bic, best[1].bic)
    return best[1]


def _describe(spec: ModalSpec) -> str:
    parts = [f"{spec.modes} modes", f"{spec.lines} lines"]
    if spec.decays:
        parts.append(f"{spec.decays} free decays")
    if spec.drifting:
        parts.append(f"{spec.drift} drift")
    parts.append(f"{spec.noise} noise" + ("" if spec.white else " without white noise"))
    if spec.gain:
        parts.append(f"gain drift ({spec.gain} cosines)")
    return ", ".join(parts)


def _row(step: int, what: str, fit: OrderFit, before: float | None, refit: str, kept: bool) -> dict[str, Any]:
    return {
        "step": step,
        "tried": what,
        "order": _describe(fit.spec),
        "modes": fit.spec.modes,
        "lines": fit.spec.lines,
        "decays": fit.spec.decays,
        "drift": fit.spec.drift,
        "noise": fit.spec.noise,
        "gain": fit.spec.gain,
        "white": fit.spec.white,
        "k": fit.k,
        "log_likelihood": float(fit.log_likelihood),
        "bic": float(fit.bic),
        "delta_bic": None if before is None else float(fit.bic - before),
        "fit": refit,
        "kept": bool(kept),
    }

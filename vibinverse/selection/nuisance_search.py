"""Which nuisance terms a scene's model needs, chosen by the data (`search_nuisance`): the same
criterion as the modal model's order (`vibinverse.model_order`),

    BIC = -2 ln L_max + k ln n      (k free parameters, n observed samples),

over the moves of `vibinverse.selection.moves` (coloured noise, drift, gain drift added; AR(1) and
1/f, walk and integrated walk exchanged; the white noise removed beside a coloured noise; a term
removed). It starts from the scene's model with what the table's `nuisance` gives (white noise by
default) at its MAP (`vibinverse.pipeline.run`, method casadi), and at each step fits every
proposal: first with only its new parameters and the noise levels free, the rest held at the
current optimum (cheap, and a lower bound on its gain), then, for proposals within 0.5 ln n of
lowering the BIC that way, with every parameter free (`vibinverse.optimize.maximize`: maximum
likelihood inside the priors' support, in the Posterior's unconstrained space), from there and, when
the scene's own values have left their spectral starts, from the proposal's own spectral start too
(`_fresh_start`: the current reading was made without the proposal's term), the larger maximum kept. The proposal that
lowers the BIC most is taken; the search stops when none does (or after MAX_STEPS). A key the user
fixes (`noise`, `drift`, `gain`, `white` in the table or on the command line) is not searched; with
all four fixed there is no search.

Clean data pay one MAP and a few partial fits (seconds). The criterion table (`NuisanceSearch.
criterion`: each proposal, its BIC, kept or not) goes to the fit's `diagnostics["nuisance_search"]`
and the report.
"""

from __future__ import annotations

import copy
import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from vibinverse.errors import DataError, SceneError, Unsupported
from vibinverse.io.series import Series
from vibinverse.models.base import SignalModel, build_model
from vibinverse.optimize import maximize
from vibinverse.posterior import Posterior
from vibinverse.priors import Prior
from vibinverse.selection.moves import MOVES
from vibinverse.terms.nuisance import SPEC_KEYS, NuisanceSpec

logger = logging.getLogger(__name__)

MAX_STEPS = 6
SCREEN_MARGIN = 0.5  # x ln n: a partial fit this close to lowering the BIC is refitted in full
FRESH_APART = 0.05  # a full refit also starts from the spectral start when a scene value is this far (relative)


@dataclass
class Reading:
    """A fitted set of nuisance terms: its spec, maximum-likelihood values, ln L_max and k."""

    spec: NuisanceSpec
    values: dict[str, float]
    log_likelihood: float
    k: int
    n: int

    @property
    def bic(self) -> float:
        return -2.0 * self.log_likelihood + self.k * math.log(self.n)


@dataclass
class NuisanceSearch:
    """The chosen terms, the criterion table and the seconds the search took."""

    chosen: Reading
    criterion: list[dict[str, Any]] = field(default_factory=list)
    seconds: float = 0.0

    def table(self) -> dict[str, Any]:
        """The `nuisance` table of the chosen terms, their optimum as the fit's start."""
        names = set(self.chosen.spec.terms(level_free=False).names()) - {"noise.sigma"}  # a scene's: gain.a0 too
        start = {n: v for n, v in self.chosen.values.items() if n in names}
        return {**self.chosen.spec.table(), **({"start": start} if start else {})}


def fixed_keys(table: dict[str, Any]) -> frozenset[str]:
    """The nuisance keys the table fixes."""
    return frozenset(k for k in SPEC_KEYS if k in (table.get("nuisance") or {}))


def wanted(table: dict[str, Any], model_class: type) -> bool:
    """Whether a fit of this table searches its nuisance terms: the model takes them and the table
    leaves one of them open."""
    return bool(getattr(model_class, "accepts_nuisance", False)) and fixed_keys(table) != frozenset(SPEC_KEYS)


def _with_spec(table: dict[str, Any], spec: NuisanceSpec) -> dict[str, Any]:
    out = copy.deepcopy(table)
    out["nuisance"] = {**(out.get("nuisance") or {}), **spec.table()}
    return out


def _posterior(scene_model: SignalModel, spec: NuisanceSpec, free: dict[str, Prior] | None) -> Posterior:
    """The posterior of the scene's model with the terms of `spec` (`SignalModel.with_nuisance`);
    the analyst's free parameters, the nuisance terms' beside them."""
    m = scene_model.with_nuisance({**(scene_model.base.get("nuisance") or {}), **spec.table()})
    priors = None if free is None else {**m.nuisance_priors(), **free}
    return Posterior(m, priors)


def _fit(post: Posterior, start: dict[str, float], free: list[str], spec: NuisanceSpec) -> Reading:
    """ln L_max over `free` from `start` (the others held), by `maximize` in z."""
    space = post.space
    z0 = space.to_z({n: p.inside(start[n]) for n, p in zip(space.names, space.priors)})
    loglike = lambda z: post.model.log_likelihood(space.from_z(z))
    idx = [space.names.index(n) for n in free if n in space.names]
    ll, z = maximize(
        loglike, z0, idx, bounded=[math.isfinite(p.bounds[0]) and math.isfinite(p.bounds[1]) for p in space.priors]
    )
    return Reading(spec, space.from_z(z), float(ll), len(space.names), int(np.isfinite(post.series.intensity).sum()))


def search_nuisance(
    table: dict[str, Any], series: Series, free: dict[str, Prior] | None = None, model: str | None = None
) -> NuisanceSearch:
    """The nuisance terms the data need beside the scene's model (module docstring)."""
    from vibinverse.pipeline import run

    t0 = time.perf_counter()
    fixed = fixed_keys(table)
    spec = NuisanceSpec.from_table(table)
    scene_model = build_model(_with_spec(table, spec), series, model)
    post = _posterior(scene_model, spec, free)
    base = run(post, "casadi", progress=False)
    current = _fit(post, base.point, list(post.space.names), spec)
    criterion = [
        _row(0, "the scene's model" + (f" with {spec.describe()}" if spec.describe() else ""), current, None, True)
    ]
    seen = {spec}
    ln_n = math.log(current.n)
    for step in range(1, MAX_STEPS + 1):
        tried: list[tuple[str, Reading]] = []
        for move in MOVES:
            for what, proposal in move.proposals(current.spec, fixed):
                if proposal in seen:
                    continue
                seen.add(proposal)
                try:
                    cand = _posterior(scene_model, proposal, free)
                except (SceneError, DataError, Unsupported) as exc:
                    logger.info("nuisance search: %s not tried (%s)", what, exc)
                    continue
                guesses = cand.model.guesses(cand.bounds)
                guess = guesses[0]
                start = {n: current.values.get(n, guess.get(n, math.nan)) for n in cand.space.names}
                new = [n for n in cand.space.names if n not in current.values]
                partial = _fit(cand, start, [*new, *_noise_names(cand)], proposal)
                if partial.bic < current.bic + SCREEN_MARGIN * ln_n:
                    names = list(cand.space.names)
                    fits = [partial, _fit(cand, partial.values, names, proposal)]
                    fresh = _fresh_start(cand, guesses, partial.values)
                    if fresh is not None:
                        fits.append(_fit(cand, fresh, names, proposal))
                    tried.append((what, max(fits, key=lambda r: r.log_likelihood)))
                else:
                    tried.append((what, partial))
        if not tried:
            break
        what, best = min(tried, key=lambda r: r[1].bic)
        improved = best.bic < current.bic
        for w, r in tried:
            criterion.append(_row(step, w, r, current.bic, improved and r is best))
        if not improved:
            break
        logger.info("nuisance search: %s (BIC %.1f -> %.1f)", what, current.bic, best.bic)
        current = best
        seen = {current.spec} | seen
    return NuisanceSearch(current, criterion, time.perf_counter() - t0)


def _fresh_start(post: Posterior, guesses: list[dict[str, float]], values: dict[str, float]) -> dict[str, float] | None:
    """A second start of the proposal's full fit: the proposal's own spectral start (`guesses`,
    its terms' starts included), the one of highest likelihood (one evaluation each); None when
    the scene's values are at one of them already (within FRESH_APART). The current optimum was
    fitted without the proposal's term, and its reading can be what the term would explain: a gain
    drift read by the white-noise model as a slow tilt resonance (0.2 Hz, its excitation at the
    prior's top) stayed so when the gain drift was added and everything freed from there (ln L
    -4084 against -3708 from the spectral start)."""
    nuisance = set(post.model.nuisance_priors()) | {"noise.sigma"}
    space = post.space
    best, best_ll = None, -math.inf
    for guess in guesses:
        scene = [n for n in space.names if n not in nuisance and n in guess and math.isfinite(guess[n])]
        apart = [
            abs(guess[n] - values[n]) > FRESH_APART * max(abs(guess[n]), abs(values[n]))
            for n in scene
            if not n.endswith("phase")
        ]
        if not any(apart):
            return None
        start = {n: guess[n] if n in guess and math.isfinite(guess[n]) else values[n] for n in space.names}
        inside = {n: p.inside(start[n]) for n, p in zip(space.names, space.priors)}
        ll = post.model.log_likelihood(inside)
        if np.isfinite(ll) and ll > best_ll:
            best, best_ll = start, float(ll)
    return best


def _noise_names(post: Posterior) -> list[str]:
    """The noise levels every partial fit frees beside a proposal's own parameters."""
    return [n for n in post.space.names if n == "noise.sigma" or n.endswith(".noise_rms")]


def _row(step: int, what: str, r: Reading, before: float | None, kept: bool) -> dict[str, Any]:
    return {
        "step": step,
        "tried": what,
        "terms": r.spec.describe(),
        **r.spec.table(),
        "k": r.k,
        "log_likelihood": float(r.log_likelihood),
        "bic": float(r.bic),
        "delta_bic": None if before is None else float(r.bic - before),
        "kept": bool(kept),
    }

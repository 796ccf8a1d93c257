"""Fitting one series: the scene table and the posterior a fit needs (the modal model's order chosen
from the data when no scene fixes it), then the pipeline. `vibinverse.api.fit` calls it for a series
and `vibinverse.imaging.joint_fit` for the combined series of many pixels."""

from __future__ import annotations

import copy
import logging
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from threadpoolctl import threadpool_limits

from vibinverse.errors import InputError, scene_errors
from vibinverse.io.scenes import load_scene
from vibinverse.io.series import Series, load_series
from vibinverse.models import build_model
from vibinverse.parallel import default_workers
from vibinverse.posterior import Posterior
from vibinverse.priors import Prior, parse_free, parse_prior
from vibinverse.result import FitResult

logger = logging.getLogger(__name__)

SceneLike = str | Path | Mapping[str, Any]
SeriesLike = str | Path | Series


def scene_table(scene: SceneLike, overrides: Sequence[str] = ()) -> dict[str, Any]:
    if isinstance(scene, Mapping):
        from forward.validation import check_depth

        with scene_errors():
            check_depth(dict(scene), "scene")  # before copying: a deep or cyclic table would recurse
        if overrides:
            from forward.scene_file import apply_overrides

            with scene_errors():
                return apply_overrides(copy.deepcopy(dict(scene)), list(overrides))
        return copy.deepcopy(dict(scene))
    return load_scene(scene, overrides)


def as_series(series: SeriesLike) -> Series:
    return series if isinstance(series, Series) else load_series(series)


def _priors(free: Mapping[str, Prior | str] | None, table: dict[str, Any]) -> dict[str, Prior] | None:
    """Free parameters: `free` (priors or prior strings), else the scene's [infer] table, else None
    (the model's defaults)."""
    out = parse_free([], table.get("infer"))
    for name, prior in (free or {}).items():
        out[name] = prior if isinstance(prior, Prior) else parse_prior(str(prior), name)
    return out or None


def _is_modal(scene: SceneLike | None, model: str | None) -> bool:
    """No scene, a `{"modal": {...}}` table, or model="modal": the scene-less modal model."""
    from vibinverse.models.modal import ModalModel

    return scene is None or model == ModalModel.name or (isinstance(scene, Mapping) and "modal" in scene)


def _modal_table(
    data: Series, scene: SceneLike | None, overrides: Sequence[str], workers: int = 1
) -> tuple[dict[str, Any], Any]:
    """The modal table to fit and the order search behind it (None when the table fixes the whole
    order): `modes`, `lines`, `drift` and `noise` given in the table are kept, the others chosen
    by `vibinverse.model_order.choose_order` (stepwise BIC), whose optimum seeds the fit. A whole
    order of modes and lines fixed without a `start` is seeded by `model_order.fit_fixed` (its
    modes and lines also built up one at a time, as the search would); free decays without an
    `onset` get the likeliest (`model_order.set_onset`), written into the table. `workers`: the
    search's threads."""
    from vibinverse.model_order import SEARCHED, choose_order, fit_fixed

    table = {"modal": {}} if scene is None else scene_table(scene, overrides)
    modal = table.get("modal")
    if modal is None:
        modal = table["modal"] = {}
    if not isinstance(modal, dict):
        raise InputError("modal: must be a table, e.g. {'modes': 2}")
    with scene_errors():
        from vibinverse.models.modal import ModalSpec

        spec = ModalSpec.from_table(table)  # one-line errors before any work
        if all(k in modal for k in SEARCHED):
            if "start" not in modal and ((spec.modes and spec.lines) or (spec.decays and spec.onset is None)):
                seeded = fit_fixed(data, spec)  # decays without an onset: the likeliest (`set_onset`)
                modal["start"] = dict(seeded.values)
                if spec.decays:
                    modal["onset"] = seeded.spec.onset
            return table, None
        order = choose_order(data, table, workers=workers)
    chosen = order.table()["modal"]
    table["modal"] = {**chosen, **{k: v for k, v in modal.items() if k in ("values",)}}
    if "windows" in modal:  # the user's line windows first (`ModalModel.line_window` takes the first holding a line)
        table["modal"]["windows"] = [*modal["windows"], *chosen.get("windows", [])]
    if "start" in modal:
        table["modal"]["start"] = {**chosen["start"], **modal["start"]}
    return table, order


def with_nuisance(
    scene: SceneLike | None, overrides: Sequence[str], nuisance: Mapping[str, Any] | None, modal: bool
) -> SceneLike | None:
    """The scene with the nuisance terms asked for (`noise`, `drift`, `gain`, `white`) written in:
    into the modal table's order without a scene, into the scene's `nuisance` table with one
    (`vibinverse.terms.nuisance.NuisanceSpec`; one-line errors for bad values)."""
    if not nuisance:
        return scene
    from vibinverse.terms.nuisance import SPEC_KEYS, NuisanceSpec

    unknown = sorted(set(nuisance) - set(SPEC_KEYS))
    if unknown:
        raise InputError(f"{unknown[0]}: not a nuisance term; allowed: noise, drift, gain, white")
    table = {"modal": {}} if scene is None else scene_table(scene, overrides)
    key = "modal" if modal else "nuisance"
    section = dict(table.get(key) or {})
    merged = {k: v for k, v in {**section, **nuisance}.items() if k in SPEC_KEYS}
    with scene_errors():
        spec = NuisanceSpec.from_table({key: merged}, key)  # one-line errors naming the key
    written = spec.table()
    section.update({k: written[k] for k in nuisance})
    if modal and "drift" in nuisance:  # the modal table's spelling: false or the kind
        section["drift"] = spec.drifting and spec.drift
    table[key] = section
    return table


def with_passband(series: Series) -> Series:
    """The series with its `passband` set when its spectrum shows a logger's anti-alias roll-off
    (`vibinverse.spectrum.passband_top`), said in its notes; else the series itself. The modal
    model is then fitted below it (Whittle's likelihood on the ordinates below it, its frequency
    priors and the order search's candidates up to it)."""
    from dataclasses import replace

    from vibinverse.spectrum import passband_top

    if series.passband is not None:
        return series
    top = passband_top(series)
    if top is None:
        return series
    note = (
        f"anti-alias roll-off: the spectrum plunges above {top:.4g} Hz (Nyquist {0.5 * series.fs:.4g} Hz), "
        f"a logger's or a decimation's low-pass filter; modes and lines are fitted below {top:.4g} Hz"
    )
    logger.info("data: %s", note)
    return replace(series, passband=top, notes=[*series.notes, note])


def build_posterior(
    series: SeriesLike,
    scene: SceneLike | None,
    free: Mapping[str, Prior | str] | None,
    model: str | None,
    overrides: Sequence[str],
    nuisance: Mapping[str, Any] | None = None,
    workers: int = 1,
) -> tuple[Posterior, Any, bool]:
    """(posterior, the search that chose the model's parts or None, whether the model is the modal
    model): the modal model's order search (`vibinverse.model_order`), or for a scene whose model
    takes nuisance terms the search of those the table leaves open
    (`vibinverse.selection.nuisance_search`). `nuisance` fixes nuisance terms (`with_nuisance`).
    `workers`: the modal order search's threads."""
    from vibinverse.models.modal import ModalModel

    data = as_series(series)
    order = None
    modal = _is_modal(scene, model)
    if nuisance:
        scene, overrides = with_nuisance(scene, overrides, nuisance, modal), ()
    if modal:
        data = with_passband(data)
        table, order = _modal_table(data, scene, overrides, workers)
        model = ModalModel.name
    else:
        table = scene_table(scene, overrides)
        with scene_errors():
            from vibinverse.models import model_class_for
            from vibinverse.selection.nuisance_search import search_nuisance, wanted

            if wanted(table, model_class_for(table, model)):
                order = search_nuisance(table, data, _priors(free, table), model)
                table["nuisance"] = {**(table.get("nuisance") or {}), **order.table()}
    with scene_errors():
        sm = build_model(table, data, model)
        for k in sm.unused_windows() if modal else []:
            lo, hi = sm.windows[k]
            logger.warning(
                "modal.windows[%d] (%.6g to %.6g Hz) holds no line's start, so it narrows nothing: "
                "start a line inside it (modal.start) or fix the order with a line there",
                k,
                lo,
                hi,
            )
        priors = _priors(free, table)
        if priors is not None:  # the nuisance terms stay free beside the parameters the analyst names
            priors = {**sm.nuisance_priors(), **priors}
        elif modal and order is not None and order.held:  # held where the filter set them (`OrderResult.held`)
            priors = {n: p for n, p in sm.default_priors().items() if n not in order.held}
        return Posterior(sm, priors), order, modal


def reading_intervals(post: Posterior, readings: Mapping[str, Any], entries: list[dict[str, Any]], seed: int) -> None:
    """For each ambiguous entry whose reading the order search fitted (`OrderResult.readings`: a
    possible line next to a resonance), that order's MAP and Laplace 90 % intervals of the entry's
    parameters, as the entry's `intervals` ({name: [q05, q95]}) and a sentence of its advice: the
    resonance's values with the line, beside the fit's without it (or, when the fit kept a possible
    line, `intervals_of` "Without the line", those without it). Priors: the model's defaults,
    the fit's own where it names the parameter."""
    from vibinverse.models.modal import ModalModel
    from vibinverse.pipeline import run

    for entry in entries:
        fit = readings.get(str(entry.get("alternative")))
        if fit is None:
            continue
        table = copy.deepcopy(post.model.base)
        table["modal"].update(fit.spec.table())
        table["modal"]["start"] = dict(fit.values)
        table["modal"]["windows"] = [*table["modal"].get("windows", []), *map(list, fit.windows)]
        with scene_errors():
            model = build_model(table, post.series, ModalModel.name)
            priors = {**model.default_priors(), **dict(zip(post.space.names, post.space.priors))}
            alt = run(
                Posterior(model, {n: priors[n] for n in model.default_priors()}), "map", seed=seed, progress=False
            )
        p = alt.summary()["parameters"]
        entry["intervals"] = {n: [p[n]["q05"], p[n]["q95"]] for n in entry.get("values", {}) if n in p}
        said = ", ".join(
            f"{n} {q[0]:.5g} to {q[1]:.5g}" for n, q in entry["intervals"].items() if n.startswith("modes[")
        )
        if said:
            label = entry.get("intervals_of", "With the line")
            entry["advice"] = f"{entry.get('advice', '')} {label}, 90 % intervals: {said}.".strip()


# one BLAS thread through a fit: its matrices are tiny (the filters are compiled loops) and OpenBLAS's
# threads only contend: an 8-parameter L-BFGS-B (the order and nuisance searches' `maximize`) took 170 ms
# with its default 2 threads on a busy 2-core machine, 9 ms with one (the benches always ran so)
@threadpool_limits.wrap(limits=1, user_api="blas")
def fit_series(
    series: SeriesLike,
    scene: SceneLike | None = None,
    *,
    method: str = "auto",
    free: Mapping[str, Prior | str] | None = None,
    model: str | None = None,
    overrides: Sequence[str] = (),
    seed: int = 0,
    chain: str | Path | None = None,
    resume: bool = False,
    workers: int | None = None,
    max_steps: int = 20000,
    progress: bool = False,
    nuisance: Mapping[str, Any] | None = None,
) -> FitResult:
    """`vibinverse.api.fit` of one series (its docstring has the options). `workers` None: the
    process's cores as threads (`default_workers`; the sampler of a likelihood that holds the GIL
    then runs in this process)."""
    from vibinverse.pipeline import check_method, run

    check_method(method)  # before the order search, which may take minutes
    threads = default_workers() if workers is None else workers
    if threads < 1 or max_steps < 1:
        raise InputError("workers and max_steps: must be >= 1")
    if resume and chain is None:
        raise InputError("resume: needs the chain (checkpoint) file of the run to continue")
    post, order, modal = build_posterior(series, scene, free, model, overrides, nuisance, threads)
    # processes (a likelihood that holds the GIL) only when asked for
    sampler = threads if workers is not None or post.model.releases_gil else 1
    with scene_errors(), tempfile.TemporaryDirectory(prefix="vibinverse-") as tmp:
        result = run(
            post,
            method,
            seed=seed,
            backend=Path(chain) if chain else Path(tmp) / "chain.h5",  # no checkpoint asked for: a temporary one
            resume=resume,
            workers=sampler,
            max_steps=max_steps,
            progress=progress,
        )
    if modal:
        result.diagnostics["model_order"] = [] if order is None else order.criterion
        if order is not None and order.ambiguous:  # a line or resonance the data cannot tell from the other kind
            result.diagnostics["ambiguous"] = [*result.diagnostics.get("ambiguous", []), *order.ambiguous]
            reading_intervals(post, order.readings, result.diagnostics["ambiguous"], seed)
        result.data["components"] = post.model.components(result.point)
        if order is not None:
            result.timing["model_order_s"] = order.seconds
            if order.capped:  # the record holds more modes or lines than the search may add
                result.diagnostics["order_capped"] = order.capped
            held = {n: v for n, v in order.held.items() if n not in post.space.names}
            if held:  # values held where the search set them, no interval (`OrderResult.held`)
                why = order.held_why
                result.diagnostics["held"] = {n: {"value": v, "why": why[n][1]} for n, v in held.items()}
    elif order is not None:  # a scene's nuisance terms, chosen by the data
        result.diagnostics["nuisance_search"] = order.criterion
        result.timing["nuisance_search_s"] = order.seconds
    return result

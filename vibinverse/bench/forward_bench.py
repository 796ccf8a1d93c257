"""Forward model: the dense reference against the scene compiler, side by side.

Speed ratios, not absolute times, are the result (machines are noisy); every row reports the error
of the fast path against the reference computed in the same run.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any

import numpy as np

from forward.reduce import DEFAULT_RTOL, compile_scene
from forward.render import pixel_signal
from forward.scene_file import load_scene

LOG = logging.getLogger(__name__).info

SCENES = ("roof_elastic", "glass_brewster", "roof_frame", "ground_rayleigh")
N_SAMPLES = 4000


def _scene(path: Path, resolution: int, n_samples: int):
    fs = load_scene(path)[0].sampling.fs
    return load_scene(path, [f"footprint.resolution={resolution}", f"sampling.duration={n_samples / fs!r}"])[0]


def _timed(fn) -> tuple[Any, float]:
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def forward_rows(
    scene_dir: Path, resolution: int, n_samples: int = N_SAMPLES, rtol: float = DEFAULT_RTOL, log=LOG
) -> list[dict]:
    """One row per example scene: dense reference vs fast path at the same resolution."""
    rows = []
    for name in SCENES:
        scene = _scene(scene_dir / f"{name}.toml", resolution, n_samples)
        ref, t_ref = _timed(lambda: pixel_signal(scene, seed=0))
        compiled, t_fast = _timed(lambda: compile_scene(scene, rtol=rtol, seed=0))
        fast, t_eval = _timed(compiled.signal)
        err = float(np.abs(fast - ref).max() / np.ptp(ref))
        row = {
            "scene": name,
            "subpixels": resolution**2,
            "samples": n_samples,
            "reference_s": t_ref,
            "fast_s": t_fast + t_eval,
            "speedup": t_ref / (t_fast + t_eval),
            "rel_error": err,
            "paths": {s.name: s.kind for s in compiled.surfaces},
        }
        log(
            f"  {name:<16} reference {t_ref:7.2f} s   fast {row['fast_s']:7.3f} s   speedup {row['speedup']:7.0f}x"
            f"   rel_error {err:.1e}   ({', '.join(f'{k}: {v}' for k, v in row['paths'].items())})"
        )
        rows.append(row)
    return rows


def scaling_rows(scene_dir: Path, resolutions=(64, 256, 1024), samples=(1_000, 10_000, 100_000), log=LOG) -> list[dict]:
    """Fast-path time of the elastic roof over T samples and N subpixels: O(T + N), not O(T N)."""
    rows = []
    for res in resolutions:
        for n in samples:
            scene = _scene(scene_dir / "roof_elastic.toml", res, n)
            _, t = _timed(lambda: compile_scene(scene, seed=0).signal())
            rows.append({"scene": "roof_elastic", "subpixels": res * res, "samples": n, "fast_s": t})
            log(f"  N = {res}^2, T = {n:>6}: {t:7.3f} s")
    return rows


def speed_error_rows(scene_dir: Path, ref_res: int, n: int = 1000, coarse=(16, 32, 64), log=LOG) -> list[dict]:
    """Error against time for the fast path at several rtol and for the dense path at several
    resolutions, all against one dense reference (elastic roof)."""
    path = scene_dir / "roof_elastic.toml"
    scene = _scene(path, ref_res, n)
    ref = pixel_signal(scene, seed=0)
    ptp = np.ptp(ref)
    rows = []
    for rtol in (1e-2, 1e-4, 1e-6, 1e-9):
        out, t = _timed(lambda: compile_scene(scene, rtol=rtol, seed=0).signal())
        rows.append(
            {
                "method": "fast",
                "setting": f"rtol={rtol:g}",
                "time_s": t,
                "rel_error": float(np.abs(out - ref).max() / ptp),
            }
        )
    for res in coarse:
        coarse = _scene(path, res, n)
        out, t = _timed(lambda: pixel_signal(coarse, seed=0))
        rows.append(
            {
                "method": "dense",
                "setting": f"{res}x{res}",
                "time_s": t,
                "rel_error": float(np.abs(out - ref).max() / ptp),
            }
        )
    for r in rows:
        log(f"  {r['method']:<5} {r['setting']:<11} {r['time_s']:8.3f} s   rel_error {r['rel_error']:.1e}")
    return rows


def plot_speed_error(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4.2), constrained_layout=True)
    for method, marker in (("fast", "o"), ("dense", "s")):
        sel = [r for r in rows if r["method"] == method]
        ax.loglog([r["time_s"] for r in sel], [max(r["rel_error"], 1e-17) for r in sel], marker=marker, label=method)
        for r in sel:
            ax.annotate(
                r["setting"],
                (r["time_s"], max(r["rel_error"], 1e-17)),
                fontsize=7,
                xytext=(4, 2),
                textcoords="offset points",
            )
    ax.set(xlabel="wall time (s)", ylabel="max |error| / peak-to-peak", title="elastic roof: speed against error")
    ax.legend()
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)


def run(scene_dir: Path, quick: bool, log=LOG) -> dict:
    """The whole forward bench: quick uses 128^2 instead of 256^2 subpixels for the references."""
    res = 128 if quick else 256
    log(f"forward model: dense reference vs fast path, {res}x{res} subpixels, {N_SAMPLES} samples")
    out = {"forward": forward_rows(scene_dir, res, log=log)}
    log("scaling of the fast path (elastic roof):")
    out["scaling"] = scaling_rows(scene_dir, log=log)
    log("speed against error (elastic roof, 1000 samples):")
    out["speed_error"] = speed_error_rows(scene_dir, res, log=log)
    from vibinverse.bench.likelihood_bench import (
        demo_mcmc_row,
        likelihood_row,
        long_modal_fit_row,
        modal_likelihood_rows,
        response_fit_row,
    )

    log("likelihood (sec. 4.2 frame) against celerite2:")
    out["likelihood"] = likelihood_row(scene_dir / "roof_frame.toml", log=log)
    log("scene-less modal likelihood, with and without nuisance terms, against celerite2:")
    out["modal_likelihood"] = modal_likelihood_rows(log=log)
    log("likelihood of a deterministic scene (sec. 4.1 elastic roof) against dense rendering:")
    out["response_likelihood"] = response_fit_row(scene_dir / "roof_elastic.toml", log=log)
    from vibinverse.bench.design_bench import design_row

    n = 30 if quick else 100
    log(f"design sweep {n}x{n} (reduced model, analytic Fisher):")
    out["design"] = design_row(scene_dir / "roof_elastic.toml", n, log=log)
    if quick:  # keeps --quick under 3 minutes; the full bench measures it
        out["demo_mcmc"] = out["long_modal_fit"] = out["hour_fit"] = None
        log("demo MCMC to convergence, default fits of a 36 000- and a 720 000-sample record: skipped with --quick")
    else:
        log("demo MCMC to convergence:")
        out["demo_mcmc"] = demo_mcmc_row(scene_dir / "roof_frame.toml", log=log)
        log("default fit of a 36 000-sample three-mode record (no scene):")
        out["long_modal_fit"] = long_modal_fit_row(log=log)
        log("default fit of a one-hour 200 Hz record (three modes, a random-walk drift; no scene):")
        out["hour_fit"] = long_modal_fit_row(log=log, hour=True)
    return out


def table(result: dict[str, Any]) -> str:
    """`run`'s result (bench.json) as fixed-width text: the forward model's fast path against the
    dense reference per scene, its scaling, speed against error, the likelihoods against celerite2
    and dense rendering, the design sweep, and the demo MCMC and the long-record default fit ("-"
    where the run skipped them: `--quick`). Pure: reads `result` only."""
    fmt = lambda v, f: format("-", f">{f.split('.')[0]}") if v is None else format(v, f)
    out = ["forward model: dense reference against the fast path (same scene, same motion, one run)"]
    out.append(
        f"{'scene':<17}{'subpixels':>10}{'samples':>8}{'ref_s':>9}{'fast_s':>9}{'speedup':>9}{'rel_error':>10}  paths"
    )
    for r in result.get("forward", []):
        paths = ", ".join(f"{k}: {v}" for k, v in r["paths"].items())
        out.append(
            f"{r['scene']:<17}{r['subpixels']:>10}{r['samples']:>8}{r['reference_s']:9.2f}{r['fast_s']:9.3f}"
            f"{r['speedup']:8.0f}x{r['rel_error']:10.1e}  {paths}"
        )
    scaling = result.get("scaling", [])
    if scaling:
        samples = sorted({r["samples"] for r in scaling})
        out += ["", "fast path's seconds, elastic roof: subpixels (rows) x samples (columns)"]
        out.append(f"{'subpixels':<10}" + "".join(f"{n:>10}" for n in samples))
        for n_sub in sorted({r["subpixels"] for r in scaling}):
            by = {r["samples"]: r["fast_s"] for r in scaling if r["subpixels"] == n_sub}
            out.append(f"{n_sub:<10}" + "".join(fmt(by.get(n), "10.3f") for n in samples))
    if result.get("speed_error"):
        out += ["", "speed against error, elastic roof (against one dense reference)"]
        out.append(f"{'method':<7}{'setting':<12}{'time_s':>9}{'rel_error':>10}")
        out += [
            f"{r['method']:<7}{r['setting']:<12}{r['time_s']:9.3f}{r['rel_error']:10.1e}" for r in result["speed_error"]
        ]
    out += ["", "likelihoods against celerite2 (microseconds per evaluation; ratio = ours / celerite2)"]
    out.append(f"{'model':<40}{'samples':>8}{'ours_us':>9}{'cel2_us':>9}{'ratio':>7}{'goal':>6}")
    like = result.get("likelihood")
    if like:
        out.append(
            f"{'sec. 4.2 frame (mean + Kalman)':<40}{like['samples']:>8}{like['ours_us']:9.0f}"
            f"{fmt(like.get('celerite2_us'), '9.0f')}{fmt(like.get('ratio'), '7.2f')}{'-':>6}"
        )
        out.append(
            f"{'sec. 4.2 frame (Kalman filter alone)':<40}{like['samples']:>8}{like['ours_filter_only_us']:9.0f}"
            f"{fmt(like.get('celerite2_us'), '9.0f')}{fmt(like.get('filter_ratio'), '7.2f')}{'-':>6}"
        )
    for r in result.get("modal_likelihood") or []:
        out.append(
            f"{'modal: ' + r['model']:<40}{r['samples']:>8}{r['ours_us']:9.0f}{r['celerite2_us']:9.0f}"
            f"{r['ratio']:7.2f}{r['goal']:6.1f}"
        )
    resp = result.get("response_likelihood")
    if resp:
        out += ["", "deterministic scene (sec. 4.1 elastic roof): one likelihood against dense rendering"]
        out.append(
            f"samples {resp['samples']}: ours {resp['ours_us']:.0f} us, dense {resp['dense_us'] / 1e3:.0f} ms "
            f"({resp['speedup']:.0f}x); max error {resp['max_error_over_sigma']:.1e} sigma; MAP fit "
            f"{resp['map_s']:.1f} s, errors {min(resp['map_error_sd'].values()):+.1f} .. "
            f"{max(resp['map_error_sd'].values()):+.1f} sd"
        )
    design = result.get("design")
    if design:
        per = ", ".join(f"{w} worker(s) {ms:.2f} ms" for w, ms in design["ms_per_configuration"].items())
        out += ["", f"design sweep, {design['configurations']} configurations: {per} per configuration"]
    demo = result.get("demo_mcmc")
    out.append("")
    if demo is None:
        out.append("demo MCMC to convergence: - (skipped with --quick)")
    else:
        out.append(
            f"demo MCMC to convergence: {demo['wall_s']:.1f} s ({demo['mcmc_s']:.1f} s MCMC), {demo['n_steps']} "
            f"steps, converged {demo['converged']}, R-hat {demo['rhat_max']:.3f}, ESS {fmt(demo['ess_min'], '.0f')}"
        )
    for key, what in (
        ("long_modal_fit", "a long three-mode record"),
        ("hour_fit", "a one-hour 200 Hz record (three modes, random-walk drift)"),
    ):
        long = result.get(key)
        if long is None:
            out.append(f"default fit of {what}: - (skipped with --quick)")
            continue
        stages = ", ".join(f"{k} {v:.1f} s" for k, v in long["timing"].items() if isinstance(v, (int, float)))
        out.append(
            f"default fit of {what}, {long['samples']} samples, {long.get('workers', 1)} thread(s): "
            f"{long['wall_s']:.1f} s "
            f"(goal <= {long['goal_s']:.0f} s; {stages}); {long['modes_found']} modes, largest frequency error "
            f"{fmt(long['max_frequency_error'], '.1e')}, intervals hold the truth: {long['intervals_hold_truth']}, "
            f"posterior by {long['approximation']}"
        )
    return "\n".join(out)

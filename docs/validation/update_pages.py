"""Regenerate the validation pages' measured tables and figures from the bench's JSON output, so that
no number on them is typed by hand. Run the benches into one directory, then this script on it:

    vibinverse bench --realdata --quick -o bench      # realdata.md
    vibinverse bench --oma --quick -o bench           # oma.md
    vibinverse bench --robustness --quick -o bench    # robustness.md (the full run: without --quick)
    vibinverse bench --estimators --quick -o bench    # estimators.md
    vibinverse bench --quick -o bench                 # speed.md, its first table
    vibinverse bench --imaging --quick -o bench       # speed.md, its imaging table
    vibinverse bench --calibration -o bench           # calibration.md (hours; --quick: a smoke test)
    # oma.md's calibration tables (the examples' JSON):
    python examples/oma_calibration.py 50 three_storey close_pair --quick -o bench/oma_calibration.json
    python examples/io_calibration.py 50 200 0.05 1.0 -o bench/io_calibration.json
    python docs/validation/update_pages.py bench

For every bench whose JSON is in the directory (the others are skipped, and said so, and their pages
left as they are) it writes a copy of the JSON beside its page (machine paths made relative; the
robustness bench's per-fit records left out, as its table does not use them), the bench's figure (if
it has one), and the page's table between its two markers (`<!-- NAME table: update_pages.py -->` and
`<!-- end of the NAME table -->`), made by the bench's own table function (`BLOCKS`; realdata.md
and oma.md's first table by `update_realdata` and `update_oma`; oma.md's calibration tables, from
the two examples' JSON, as Markdown by `oma_calibration_table` and `io_calibration_table`).
tests/test_docs.py checks that each page's table is the one its stored JSON gives."""

from __future__ import annotations

import importlib
import json
import re
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vibinverse.bench.realdata_bench import plot, table

HERE = Path(__file__).resolve().parent
REALDATA_PAGE = HERE / "realdata.md"
REALDATA_JSON = HERE / "realdata_quick.json"
REALDATA_FIGURE = HERE / "realdata_quick.png"
BEGIN, END = "<!-- realdata table: update_pages.py -->", "<!-- end of the realdata table -->"
OMA_PAGE, OMA_JSON, OMA_FIGURE = HERE / "oma.md", HERE / "oma_quick.json", HERE / "oma_quick.png"
OMA_BEGIN, OMA_END = "<!-- oma table: update_pages.py -->", "<!-- end of the oma table -->"


def relative(result: dict[str, Any]) -> dict[str, Any]:
    """The bench's result with every file path relative to the corpus (no machine's directories)."""

    def cut(path: str) -> str:
        marker = "realdata-dev/"
        return path.split(marker, 1)[1] if marker in path else Path(path).name

    rows = [{**r, "path": cut(r["path"])} if "path" in r else r for r in result["rows"]]
    settings = dict(result.get("settings", {}))
    if "files" in settings:
        settings["files"] = [cut(f) for f in settings["files"]]
    return {**result, "rows": rows, "settings": settings}


def table_block(result: dict[str, Any]) -> str:
    """The page's block: the markers around the bench's table."""
    return f"{BEGIN}\n```\n{table(result)}\n```\n{END}"


def update_realdata(bench_dir: Path) -> None:
    """realdata_quick.json, realdata_quick.png and realdata.md's table from bench_dir/realdata.json."""
    source = bench_dir / "realdata.json"
    if not source.is_file():
        raise SystemExit(f"update_pages: no {source}; run `vibinverse bench --realdata --quick -o {bench_dir}` first")
    result = relative(json.loads(source.read_text()))
    splice(REALDATA_PAGE, BEGIN, END, table_block(result))
    REALDATA_JSON.write_text(json.dumps(result, indent=1) + "\n")
    plot(result, REALDATA_FIGURE)


def splice(page_path: Path, begin: str, end: str, block: str) -> None:
    """Replace the block between the markers `begin` and `end` (each once on the page) by `block`."""
    page = page_path.read_text()
    if page.count(begin) != 1 or page.count(end) != 1:
        raise SystemExit(f"update_pages: {page_path} needs the markers {begin!r} and {end!r} once each")
    head, rest = page.split(begin)
    page_path.write_text(head + block + rest.split(end, 1)[1])


def oma_block(result: dict[str, Any]) -> str:
    """oma.md's block: the markers around the OMA bench's table."""
    from vibinverse.bench.oma_bench import table as oma_table

    return f"{OMA_BEGIN}\n```\n{oma_table(result)}\n```\n{OMA_END}"


def update_oma(bench_dir: Path) -> None:
    """oma_quick.json, oma_quick.png and oma.md's table from bench_dir/oma.json."""
    from vibinverse.bench.oma_bench import plot as oma_plot

    result = json.loads((bench_dir / "oma.json").read_text())
    splice(OMA_PAGE, OMA_BEGIN, OMA_END, oma_block(result))
    OMA_JSON.write_text(json.dumps(result, indent=1) + "\n")
    oma_plot(result, OMA_FIGURE)


# ---- the pages made the same way from the other benches: one `Block` each ----------------------


def _bench(module: str, name: str) -> Callable[..., Any]:
    """vibinverse.bench.<module>.<name>, imported when called (each bench imports its own peers)."""
    return lambda *args: getattr(importlib.import_module(f"vibinverse.bench.{module}"), name)(*args)


def _seconds(result: dict[str, Any]) -> str:
    s = result.get("seconds")
    return f"; it ran {s / 60:.1f} min" if isinstance(s, (int, float)) else ""


def _robustness_run(result: dict[str, Any]) -> str:
    st = result.get("settings", {})
    run = "quick run" if st.get("quick") else "full run"
    cmd = "vibinverse bench --robustness" + (" --quick" if st.get("quick") else "")
    seeds = st.get("seeds", ["?", "?"])
    return (
        f"The {run} (`{cmd}`): {st.get('n', '?')} data sets per case (seeds {seeds[0]}-{seeds[1]})"
        f"{', at half the durations' if st.get('quick') else ''}, methods {', '.join(st.get('methods', []))}"
        f"{_seconds(result)}. The cases:\n\n"
        + "\n".join(f"- `{name}`: {what}" for name, what in st.get("cases", {}).items())
    )


def _robustness_stored(result: dict[str, Any]) -> dict[str, Any]:
    """robustness.json without its per-fit records (`fits`, and the scene column's if there is one:
    200 in a quick run, thousands in a full one), which the table and the figure do not use; the
    bench's own JSON keeps them."""
    kept = {k: v for k, v in result.items() if k != "fits"}
    if isinstance(kept.get("scene"), dict):
        kept["scene"] = {k: v for k, v in kept["scene"].items() if k != "fits"}
    return kept


def _estimators_run(result: dict[str, Any]) -> str:
    st = result.get("settings", {})
    mcmc = st.get("mcmc_seeds")
    snrs = "/".join(str(s) for s in st.get("mcmc_snrs", []))
    return (
        f"This run: {st.get('n_seeds', '?')} data sets per method and SNR, {st.get('n_coverage_casadi', '?')} for "
        f"casadi (whose coverage is scored), {mcmc} for importance sampling and emcee at SNR {snrs}"
        f"{_seconds(result)}."
    )


def _speed_run(result: dict[str, Any]) -> str:
    forward = result.get("forward") or [{}]
    sub = forward[0].get("subpixels")
    quick = result.get("long_modal_fit") is None and result.get("demo_mcmc") is None
    side = f"{round(sub**0.5)}²" if sub else "?"
    return (
        f"This run: {'`vibinverse bench --quick`' if quick else '`vibinverse bench`'}, references at {side} "
        f"subpixels{', without the demo MCMC and the long-record fits (the full run measures them)' if quick else ''}."
    )


def _imaging_run(result: dict[str, Any]) -> str:
    quick = result.get("quick")
    return (
        f"This run: `vibinverse bench --imaging{' --quick' if quick else ''}`"
        f"{' (half the frames for the detection and the fits, the shorter real video)' if quick else ''}"
        f"{_seconds(result)}."
    )


def _imaging_stored(result: dict[str, Any]) -> dict[str, Any]:
    """imaging.json with the skipped real videos' reasons stripped of the machine's directories."""
    reals = [
        {**r, "skipped": re.sub(r"/\S*/(realdata-dev/)?", "", r["skipped"])} if "skipped" in r else r
        for r in result.get("real_videos", [])
    ]
    return {**result, "real_videos": reals}


def _calibration_run(result: dict[str, Any]) -> str:
    st = result.get("settings", {})
    limits = st.get("fit_limit_s")
    limit = ", ".join(f"{v:g} s" for v in dict.fromkeys(limits.values())) if isinstance(limits, dict) else f"{limits} s"
    sets_text = _bench("calibration_bench", "sets_text")
    return (
        f"This run: `vibinverse bench --calibration{' --quick' if st.get('quick') else ''}`, "
        f"{sets_text(result)}, a fit limit of {limit}{_seconds(result)}. The cases:\n\n"
        + "\n".join(f"- `{name}`: {what}" for name, what in st.get("cases", {}).items())
    )


# ---- oma.md's calibration tables: from the JSON of examples/oma_calibration.py and io_calibration.py


def _cov(entry: dict[str, Any] | None, key: str = "coverage", se: str = "se") -> str:
    """`coverage ± se` of a coverage entry (3 decimals), "-" where nothing was counted."""
    if not entry or entry.get(key) is None:
        return "-"
    return f"{entry[key]:.3f} ± {entry[se]:.3f}"


def _fraction(x: float | None) -> str:
    return "-" if x is None else f"{x:.3f}"


def _span(seconds: float) -> str:
    return f"{seconds / 60:g} min" if seconds % 60 == 0 else f"{seconds:g} s"


def _oma_case(r: dict[str, Any]) -> str:
    return f"{r['case']} ({r['modes']} modes, {r['channels']} channels, {_span(r['duration'])} at {r['fs']:g} Hz)"


def oma_calibration_table(result: dict[str, Any]) -> str:
    """Per case of examples/oma_calibration.py's JSON: the data sets (failed fits), the fraction of
    true modes found, the intervals counted (f / ζ / shape components) and the 90 % intervals'
    coverage ± its binomial standard error, as a Markdown table."""
    lines = [
        "| case | data sets (failed) | modes found | intervals (f / ζ / shape) | f | ζ | shape components |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in result["cases"]:
        f, z, sh = r["frequency"], r["damping_ratio"], r["shape"]
        lines.append(
            f"| {_oma_case(r)} | {r['n_sets']} ({r['failed']}) | {_fraction(r['found'])} "
            f"| {f['n']} / {z['n']} / {sh['n']} | {_cov(f)} | {_cov(z)} | {_cov(sh)} |"
        )
    return "\n".join(lines)


def _oma_calibration_run(result: dict[str, Any]) -> str:
    st = result.get("settings", {})
    cases = result.get("cases", [])
    quick = " --quick" if st.get("quick") else ""
    command = f"python examples/oma_calibration.py {st.get('n_sets', '?')} {' '.join(st.get('cases', []))}{quick}"
    every = all(r.get("found") == 1 and r.get("failed") == 0 for r in cases)
    without = []  # matched modes reported without an interval of f: not counted
    for r in cases:
        matched = round((r["found"] or 0.0) * r["modes"] * (r["n_sets"] - r["failed"]))
        if matched > r["frequency"]["n"]:
            without.append(f"{matched - r['frequency']['n']} of the {matched} on {r['case']}")
    no_interval = (
        f" Matched modes reported without an interval (the posterior not locally Gaussian) are not counted: "
        f"{', '.join(without)}."
        if without
        else ""
    )
    return (
        f"This run: `{command} -o bench/oma_calibration.json`, {st.get('n_sets', '?')} data sets per case"
        f"{' on the quick records' if st.get('quick') else ''}{_seconds(result)}. "
        f"{'Every true mode was found in every data set.' if every else 'Not every true mode was found.'}"
        f"{no_interval} The cases:\n\n" + "\n".join(f"- `{r['case']}`: {r['what']}" for r in cases)
    )


def io_calibration_table(result: dict[str, Any]) -> str:
    """Per noise level and mode of examples/io_calibration.py's JSON: the records, the records where
    the mode was found (the intervals counted) and where it had no interval (counted as missing the
    truth), the 90 % intervals' coverage of f and ζ ± its binomial standard error, and the z-scores'
    mean (sd), as a Markdown table."""
    lines = [
        "| sensor noise | mode | records | found (intervals) | without interval | f | ζ | z of f: mean (sd) "
        "| z of ζ: mean (sd) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]

    def z(m: dict[str, Any], name: str) -> str:
        mean, sd = m.get(f"z_{name}_mean"), m.get(f"z_{name}_sd")
        return "-" if mean is None else f"{mean:+.2f} ({sd:.2f})"

    for level in result["levels"]:
        noise = f"{100 * level['noise']:g} % of each channel's sd"
        for m in level["modes"]:
            mode = f"{m['frequency']:g} Hz, ζ {m['damping_ratio']:g}"
            cov_f = _cov(m, "coverage_frequency", "coverage_frequency_se")
            cov_z = _cov(m, "coverage_damping_ratio", "coverage_damping_ratio_se")
            lines.append(
                f"| {noise} | {mode} | {m['found'] + m['missed']} | {m['found']} | {m['no_interval']} "
                f"| {cov_f} | {cov_z} | {z(m, 'frequency')} | {z(m, 'damping_ratio')} |"
            )
    return "\n".join(lines)


def _io_calibration_run(result: dict[str, Any]) -> str:
    noises = " ".join(f"{level['noise']:g}" for level in result.get("levels", []))
    n, fs = result.get("sets", "?"), result.get("fs", 0.0)
    band = "-".join(f"{b:g}" for b in result.get("band", []))
    true_modes = result.get("true_modes", [])
    modes = "; ".join(f"{m['frequency']:g} Hz, ζ {m['damping_ratio']:g}" for m in true_modes)
    return (
        f"This run: `python examples/io_calibration.py {n} {fs:g} {noises} -o bench/io_calibration.json`, "
        f"{n} records of {result.get('duration', 0.0):g} s at {fs:g} Hz per noise level (the same seeds at each), "
        f"{len(true_modes)} modes ({modes}) on {result.get('channels', '?')} channels, analysis band {band} Hz"
        f"{_seconds(result)}."
    )


@dataclass(frozen=True)
class Block:
    """A measured block of a validation page: `source`, the JSON the bench writes (`command`), gives
    `table(result)` between the markers `<!-- NAME table: update_pages.py -->` and `<!-- end of the
    NAME table -->` of `page`, under the sentence `caption(result)` says of the run; `stored` (the
    JSON as kept beside the page, `keep(result)`) and `figure` (`plot(result, path)`; None for a table
    without a figure) beside it; the table is fixed-width text in a code block, or Markdown
    (`markdown`) set as it is."""

    name: str
    source: str
    command: str
    page: Path
    stored: Path
    figure: Path | None
    table: Callable[[dict[str, Any]], str]
    plot: Callable[[dict[str, Any], Path], None] | None
    caption: Callable[[dict[str, Any]], str]
    keep: Callable[[dict[str, Any]], dict[str, Any]] = lambda result: result
    markdown: bool = False

    @property
    def begin(self) -> str:
        return f"<!-- {self.name} table: update_pages.py -->"

    @property
    def end(self) -> str:
        return f"<!-- end of the {self.name} table -->"

    def block(self, result: dict[str, Any]) -> str:
        """The page's block made from `result` (the stored JSON): markers, the run's sentence, the table."""
        table = self.table(result) if self.markdown else f"```\n{self.table(result)}\n```"
        return f"{self.begin}\n{self.caption(result)}\n\n{table}\n{self.end}"

    def update(self, bench_dir: Path) -> None:
        """The stored JSON, the figure (if any) and the page's table from bench_dir/`source`."""
        result = self.keep(json.loads((bench_dir / self.source).read_text()))
        splice(self.page, self.begin, self.end, self.block(result))
        self.stored.write_text(json.dumps(result, indent=1) + "\n")
        if self.plot is not None and self.figure is not None:
            self.plot(result, self.figure)


BLOCKS = (
    Block(
        "robustness",
        "robustness.json",
        "vibinverse bench --robustness --quick",
        HERE / "robustness.md",
        HERE / "robustness.json",
        HERE / "robustness.png",
        _bench("robustness_bench", "table"),
        lambda result, path: _bench("robustness_bench", "plot")(result["rows"], path),
        _robustness_run,
        _robustness_stored,
    ),
    Block(
        "estimators",
        "estimators.json",
        "vibinverse bench --estimators --quick",
        HERE / "estimators.md",
        HERE / "estimators.json",
        HERE / "estimators.png",
        _bench("estimators_bench", "table"),
        lambda result, path: _bench("estimators_bench", "plot_speed_error")(result["rows"], path),
        _estimators_run,
    ),
    Block(
        "speed",
        "bench.json",
        "vibinverse bench --quick",
        HERE / "speed.md",
        HERE / "speed.json",
        HERE / "speed.png",
        _bench("forward_bench", "table"),
        lambda result, path: _bench("forward_bench", "plot_speed_error")(result["speed_error"], path),
        _speed_run,
    ),
    Block(
        "imaging",
        "imaging.json",
        "vibinverse bench --imaging --quick",
        HERE / "speed.md",
        HERE / "imaging.json",
        HERE / "imaging.png",
        _bench("imaging_bench", "table"),
        _bench("imaging_bench", "plot"),
        _imaging_run,
        _imaging_stored,
    ),
    Block(
        "calibration",
        "calibration.json",
        "vibinverse bench --calibration",
        HERE / "calibration.md",
        HERE / "calibration.json",
        HERE / "calibration.png",
        _bench("calibration_bench", "table"),
        _bench("calibration_bench", "plot"),
        _calibration_run,
        _bench("calibration_bench", "without_records"),
    ),
    Block(
        "oma calibration",
        "oma_calibration.json",
        "python examples/oma_calibration.py",
        OMA_PAGE,
        HERE / "oma_calibration.json",
        None,
        oma_calibration_table,
        None,
        _oma_calibration_run,
        markdown=True,
    ),
    Block(
        "io calibration",
        "io_calibration.json",
        "python examples/io_calibration.py",
        OMA_PAGE,
        HERE / "io_calibration.json",
        None,
        io_calibration_table,
        None,
        _io_calibration_run,
        markdown=True,
    ),
)


def main(bench_dir: Path) -> list[str]:
    """Every page whose bench JSON is in `bench_dir`; returns the JSON files used (SystemExit: none)."""
    done, skipped = [], []
    for source, update in (("realdata.json", update_realdata), ("oma.json", update_oma)):
        (done if (bench_dir / source).is_file() else skipped).append(source)
        if (bench_dir / source).is_file():
            update(bench_dir)
    for b in BLOCKS:
        (done if (bench_dir / b.source).is_file() else skipped).append(b.source)
        if (bench_dir / b.source).is_file():
            b.update(bench_dir)
    if not done:
        raise SystemExit(f"update_pages: no bench JSON in {bench_dir}; run `vibinverse bench ... -o {bench_dir}` first")
    print(f"update_pages: updated from {', '.join(done)}")  # noqa: T201
    if skipped:
        print(f"update_pages: skipped (not in {bench_dir}): {', '.join(skipped)}; their pages are unchanged")  # noqa: T201
    return done


if __name__ == "__main__":
    if len(sys.argv) != 2:
        raise SystemExit("usage: python docs/validation/update_pages.py BENCH_DIR")
    main(Path(sys.argv[1]))

"""The HTML report of a multi-channel identification: what was found first (the mode table: f and ζ
with 90 % intervals), then each mode's shape over the channels with its interval, the MAC matrix,
the figure (stabilization-style diagram, shapes, MAC) and the notes. Self-contained (the figure
inlined), escaped throughout, readable on a phone."""

from __future__ import annotations

import base64
import html
import io
from pathlib import Path

from vibinverse.oma.result import INTERVAL, OmaResult, interval_text
from vibinverse.report import CSS


def _e(value: object) -> str:
    return html.escape(str(value), quote=True)


def _figure(result: OmaResult) -> str:
    from vibinverse.oma.plots import plot_oma

    buf = io.BytesIO()
    plot_oma(result, buf)
    data = base64.b64encode(buf.getvalue()).decode("ascii")
    return f'<img alt="stabilization diagram, mode shapes and MAC" src="data:image/png;base64,{data}">'


def oma_html(result: OmaResult, source: str) -> str:
    """The page (module docstring)."""
    p = round(100 * INTERVAL)
    n = len(result.modes)
    head = (
        f"{n} mode(s) identified from {len(result.names)} channel(s) ({_e(', '.join(result.names))}), "
        f"{result.samples} samples at {result.fs:.6g} Hz, {_e(result.quantity)}; {result.seconds:.1f} s"
    )
    rows = []
    for i, m in enumerate(result.modes, 1):
        warn = "<br>".join(_e(w) for w in m.warnings)
        rows.append(
            f"<tr><td>{i}</td><td>{m.frequency:.6g}</td><td>{interval_text(*m.frequency_interval, '.6g')}</td>"
            f"<td>{m.damping_ratio:.4g}</td><td>{interval_text(*m.damping_ratio_interval, '.4g')}</td>"
            f"<td>{warn}</td></tr>"
        )
    modes = (
        f"<table><thead><tr><th>mode</th><th>f (Hz)</th><th>{p} %</th><th>ζ</th><th>{p} %</th><th>warnings</th></tr>"
        f"</thead><tbody>{''.join(rows)}</tbody></table>"
    )
    shape_head = "".join(f"<th>{i} ({m.frequency:.4g} Hz)</th>" for i, m in enumerate(result.modes, 1))
    shape_rows = []
    for c, name in enumerate(result.names):
        cells = "".join(
            f"<td>{m.shape[c]:+.3f} {interval_text(*m.shape_interval[c], '+.3f')}</td>" for m in result.modes
        )
        shape_rows.append(f"<tr><th>{_e(name)}</th>{cells}</tr>")
    shapes = f"<table><thead><tr><th>channel</th>{shape_head}</tr></thead><tbody>{''.join(shape_rows)}</tbody></table>"
    mac = result.mac
    mac_rows = "".join(
        f"<tr><th>{i + 1}</th>{''.join(f'<td>{v:.3f}</td>' for v in row)}</tr>" for i, row in enumerate(mac)
    )
    mac_html = (
        f"<table><thead><tr><th></th>{''.join(f'<th>{i + 1}</th>' for i in range(n))}</tr></thead>"
        f"<tbody>{mac_rows}</tbody></table>"
    )
    notes = "".join(f"<li>{_e(x)}</li>" for x in result.notes)
    return (
        '<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>vibinverse modal identification: {_e(Path(source).name)}</title><style>{CSS}</style></head><body>"
        f"<h1>Modal identification of {_e(Path(source).name)}</h1><p>{head}</p>"
        f"<h2>Modes</h2><div class='table-wrap'>{modes}</div>"
        f"<h2>Mode shapes (unit norm, largest component positive; {p} % intervals)</h2>"
        f"<div class='table-wrap'>{shapes}</div>"
        f"<h2>MAC between modes</h2><div class='table-wrap'>{mac_html}</div>"
        f"<h2>Stabilization diagram, shapes and MAC</h2>{_figure(result)}"
        + (f"<h2>Notes</h2><ul>{notes}</ul>" if notes else "")
        + "<p>Method: the multi-channel frequency-domain likelihood in bands (Bayesian FFT), the mode count "
        "per band by BIC, Laplace intervals at the MAP.</p></body></html>"
    )


def write_oma_report(result: OmaResult, path: str | Path, source: str) -> None:
    """Write `oma_html` to `path`."""
    Path(path).write_text(oma_html(result, source), encoding="utf-8")

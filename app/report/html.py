"""One self-contained HTML report of a test: data, checks, results and figures (PNG, base64).

An engineer can file the page as it is: no external files, no scripts. Figures are drawn
with the same functions as the GUI's views (:mod:`app.report.figures`), so a Qt application
must exist (``insitu report`` starts an off-screen one).
"""

from __future__ import annotations

import base64
import html
from collections.abc import Callable, Mapping, Sequence
from datetime import datetime
from typing import Any

import pyqtgraph as pg

from app.io.mounts import MountsFile
from app.report import figures
from app.report.analysis import Analysis
from app.report.mount_system import mount_system
from app.report.tables import (
    COMPARISON,
    SPREADS,
    check_rows,
    comparison_rows,
    contribution_lines,
    format_matrix,
    inertia_rows,
    modes_text,
    principal_rows,
    sources_line,
)
from processing.identify import IdentificationResult
from processing.results import Uncertainty

__all__ = ["build_report"]

_STYLE = """
body { font-family: sans-serif; max-width: 1000px; margin: 2em auto; color: #222; }
h1 { font-size: 1.5em; } h2 { font-size: 1.2em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; margin: 0.5em 0 1em; font-size: 0.9em; }
td, th { border: 1px solid #ccc; padding: 3px 8px; text-align: right; }
th { background: #f0f0f0; } td.l, th.l { text-align: left; }
.PASS { color: #fff; background: #009E73; font-weight: bold; text-align: center; }
.FAIL { color: #fff; background: #D55E00; font-weight: bold; text-align: center; }
.na { color: #555; background: #eee; text-align: center; }
.warn { color: #8a4b00; } img { max-width: 100%; }
"""


_LEFT = ' class="l"'


def _table(head: Sequence[str], rows: Sequence[Sequence[str]], left: int = 1) -> str:
    def cells(tag: str, values: Sequence[str]) -> str:
        return "".join(f"<{tag}{_LEFT if i < left else ''}>{html.escape(v)}</{tag}>"
                       for i, v in enumerate(values))
    body = "".join(f"<tr>{cells('td', r)}</tr>" for r in rows)
    return f"<table><tr>{cells('th', head)}</tr>{body}</table>"


def _figure(draw: Callable[[pg.PlotItem], None], alt: str) -> str:
    data = base64.b64encode(figures.render_png(draw)).decode("ascii")
    return f'<p><img alt="{html.escape(alt)}" src="data:image/png;base64,{data}"></p>'


def _checks(a: Analysis) -> str:
    rows = "".join(
        f"<tr><td class=\"l\">{html.escape(c.name)}</td>"
        f"<td class=\"{c.verdict if c.passed is not None else 'na'}\">{c.verdict}</td>"
        f"<td class=\"l\">{html.escape(c.detail)}</td></tr>"
        for c in check_rows(a)
    )
    head = '<tr><th class="l">check</th><th>verdict</th><th class="l">figures</th></tr>'
    return f"<table>{head}{rows}</table>"


def _uncertainty(u: Uncertainty | None) -> str:
    """What the ± propagate and the largest contributions; empty without an uncertainty."""
    if u is None:
        return ""
    lines = contribution_lines(u)
    out = f"<p>{html.escape(sources_line(u))}.</p>"
    if lines:
        out += ("<p>Largest contributions to the variance:</p><ul class=\"contrib\">"
                + "".join(f"<li>{html.escape(x)}</li>" for x in lines) + "</ul>")
    return out


def _mount_system(a: Analysis, mounts: MountsFile | None, excitation_hz: float | None) -> str:
    """Modes, energy decoupling and, with mounts, the rates and the torque roll axis."""
    if a.result is None:
        return ""
    try:
        ms = mount_system(a.result, mounts, excitation_hz)
    except ValueError as err:
        return f"<h2>Mount system</h2><p class=\"warn\">{html.escape(str(err))}</p>"
    parts = [f"<p class=\"warn\">{html.escape(w)}</p>" for w in ms.problems]
    parts += [
        "<h2>Rigid-body modes</h2><p>Of the identified M, K, C; damping ratios by the modal "
        "approximation. Mode shapes at O (mass-normalised) are in the result JSON.</p>",
        _table(ms.mode_head(), ms.mode_rows()),
        "<p>Kinetic-energy decoupling: percentage of each mode's kinetic energy in each DOF, "
        "at the centre of gravity, global axis directions.</p>",
        _table(("mode", *figures.DOF_LABELS), ms.energy_rows()),
    ]
    if ms.rates is not None:
        parts += ["<h2>Individual mount rates</h2><p>Non-negative least squares of the mounts' "
                  "rates on K (and C for the loss factors); 'NO': not determined by this test."
                  "</p>", _table(ms.mount_head(), ms.mount_rows(), left=2),
                  "<ul>" + "".join(f"<li>{html.escape(n)}</li>" for n in ms.mount_notes())
                  + "</ul>"]
    if ms.tra is not None:
        parts += ["<h2>Torque roll axis</h2>", _table(("quantity", "value"), ms.tra_rows(),
                                                      left=2)]
    return "".join(parts)


def _comparison(prediction: Mapping[str, Any] | None, u: Uncertainty | None) -> str:
    """The plan's predicted std beside the achieved ones; empty without a prediction."""
    if prediction is None:
        return ""
    return (f"<h2>Predicted and achieved uncertainty</h2><p>{html.escape(COMPARISON)}.</p>"
            + _table(("parameter", "unit", "predicted std", "achieved std",
                      "achieved / predicted"), comparison_rows(prediction, u), left=2))


def _matrices(r: IdentificationResult, u: Uncertainty | None) -> list[str]:
    """The K, C and D tables at O."""
    return [
        "<h2>Stiffness K at O</h2><p>N/m, N/rad, N m/m, N m/rad; DOF order x, y, z, rx, "
        f"ry, rz.{'' if r.stiffening is None else ' ' + html.escape(r.stiffening_note) + '.'}"
        "</p>",
        _table(("", *figures.DOF_LABELS),
               [(d, *row) for d, row in zip(figures.DOF_LABELS,
                                            format_matrix(r.K, u, "stiffness"),
                                            strict=True)]),
        "<h2>Damping C at O</h2><p>N s/m, N s/rad, N m s/m, N m s/rad.</p>",
        _table(("", *figures.DOF_LABELS),
               [(d, *row) for d, row in zip(figures.DOF_LABELS,
                                            format_matrix(r.C, u, "damping"),
                                            strict=True)]),
        "<h2>Structural damping D at O</h2><p>K* = K + jωC + jD; N/m, N/rad, N m/m, "
        f"N m/rad. {html.escape(r.damping_note)}.</p>",
        _table(("", *figures.DOF_LABELS),
               [(d, *row) for d, row in zip(figures.DOF_LABELS, format_matrix(r.D),
                                            strict=True)]),
    ]


def build_report(a: Analysis, title: str = "In situ identification report",
                 mounts: MountsFile | None = None, excitation_hz: float | None = None,
                 prediction: Mapping[str, Any] | None = None) -> str:
    """The HTML page of one analysis.

    Parameters
    ----------
    a : the analysis (data, identification, checks)
    title : page heading
    mounts : the mounts file, for the mount rates and the torque roll axis (optional)
    excitation_hz : excitation frequency for the isolation margins, Hz (optional)
    prediction : the run's plan's ``[prediction]`` table (``insitu plan``), shown beside
        the achieved uncertainty (optional)

    Returns
    -------
    str
        A complete HTML document with every figure embedded as a PNG ``data:`` URI.
    """
    figures.configure()
    n_r, n_e, n_f = a.frf.H.shape
    parts = [
        f"<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>{html.escape(title)}</title>"
        f"<style>{_STYLE}</style></head><body>",
        f"<h1>{html.escape(title)}</h1>",
        f"<p>Data: <b>{html.escape(a.source)}</b> — {n_r} response DOFs x {n_e} excitations, "
        f"{n_f} lines {a.frf.freq[0]:g}-{a.frf.freq[-1]:g} Hz. Method: {a.options.method}"
        f"{', physically constrained' if a.options.physical else ''}. "
        f"Written {datetime.now().isoformat(timespec='seconds')}.</p>",
        *([f"<p>{html.escape(SPREADS)}.</p>"] if a.result is not None and (
            a.result.uncertainty is not None or mounts is not None) else []),
        "<h2>Checks</h2>", _checks(a),
    ]
    r = a.result
    if r is None:
        parts.append(f"<p class=\"warn\">Identification failed: {html.escape(a.error or '')}</p>")
    else:
        p = r.properties
        u = r.uncertainty
        parts += [
            f"<p>Bands: mass line {r.mass_band[0]:g}-{r.mass_band[1]:g} Hz, stiffness "
            f"{r.stiffness_band[0]:g}-{r.stiffness_band[1]:g} Hz. Rigid-body modes: "
            + html.escape(modes_text(r.rigid_modes_hz, u)) + " Hz."
            + ("" if r.channel_delays is None
               else " " + html.escape(r.channel_delays_note[0].upper()
                                      + r.channel_delays_note[1:]) + ".")
            + "</p>",
            "<h2>Inertia parameters</h2>",
            _uncertainty(u),
            _table(("parameter", "unit", "about the CoG", "about the origin O"),
                   inertia_rows(p, u), left=2),
            "<p>Principal moments about the CoG (axes as unit vectors in the global frame):</p>",
            _table(("", "moment (kg m²)", "axis x", "axis y", "axis z"), principal_rows(p, u)),
            _comparison(prediction, u),
            *_matrices(r, u),
        ]
        parts.append(_mount_system(a, mounts, excitation_hz))
        if r.warnings:
            parts.append("<ul class=\"warn\">" + "".join(
                f"<li>{html.escape(w)}</li>" for w in r.warnings) + "</ul>")
    parts.append("<h2>Figures</h2>")
    parts.append(_figure(lambda pl: figures.draw_coherence_bars(pl, a), "coherence per FRF"))
    parts.append(_figure(lambda pl: figures.draw_coherence_freq(pl, a), "coherence"))
    parts.append(_figure(lambda pl: figures.draw_rigidity(pl, a), "rigidity check"))
    if r is not None:
        parts.append(_figure(lambda pl: figures.draw_dynamic_stiffness(pl, a), "K* translational"))
        parts.append(_figure(lambda pl: figures.draw_dynamic_stiffness(pl, a, rotational=True),
                             "K* rotational"))
        parts.append(_figure(lambda pl: figures.draw_synthesis(pl, a), "synthesised FRFs"))
    parts.append("</body></html>")
    return "\n".join(parts)

"""A campaign: many run/UFF/FRF files identified on a Dask cluster, one table row per file.

:func:`identify_file` is the task (it runs on a worker: :func:`app.pipeline.load`, then
:func:`processing.identify.fit`,
reduce to one row; a failure is the row's one-line error, never an exception);
:func:`run_campaign` maps it over the files; :func:`write_tables` writes the rows as CSV,
Parquet and HTML.
"""

from __future__ import annotations

import csv
import html
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from distributed import Client, as_completed

from app.pipeline import Settings, load
from app.report.analysis import message_of
from app.report.tables import Z95, half_width
from processing.identify import IdentificationResult, IdentifyOptions, fit

__all__ = ["COLUMNS", "TABLE_NAME", "identify_file", "result_row", "run_campaign",
           "write_tables"]

Row = dict[str, Any]

#: base name of the written tables (``campaign.csv``, ``.parquet``, ``.html``)
TABLE_NAME = "campaign"

_J = (("xx", 0, 0, 1.0), ("yy", 1, 1, 1.0), ("zz", 2, 2, 1.0),
      ("xy", 0, 1, -1.0), ("xz", 0, 2, -1.0), ("yz", 1, 2, -1.0))

#: the numeric columns: (name, uncertainty key, index, factor from the result's SI value).
#: Products of inertia with the article's sign (J_xy = integral of x y dm), as the views show
#: them; rigid modes: the first and the last of the six.
COLUMNS: tuple[tuple[str, str, tuple[int, ...], float], ...] = (
    ("mass_kg", "mass", (), 1.0),
    *((f"cog_{a}_m", "cog", (k,), 1.0) for k, a in enumerate("xyz")),
    *((f"J{n}_cog_kgm2", "inertia_cog", (i, j), s) for n, i, j, s in _J),
    *((f"J{n}_O_kgm2", "inertia_origin", (i, j), s) for n, i, j, s in _J),
    *((f"J{k + 1}_principal_kgm2", "principal_moments", (k,), 1.0) for k in range(3)),
    ("first_rigid_mode_hz", "rigid_modes_hz", (0,), 1.0),
    ("last_rigid_mode_hz", "rigid_modes_hz", (5,), 1.0),
)

#: the columns every row has, before the numbers
HEAD = ("file", "status", "error", "seconds", "skipped_runs", "checks_pass")


def _values(r: IdentificationResult) -> dict[str, Any]:
    p = r.properties
    return {"mass": p.mass, "cog": p.cog, "inertia_cog": p.inertia_cog,
            "inertia_origin": p.inertia_origin, "principal_moments": p.principal_moments,
            "rigid_modes_hz": r.rigid_modes_hz}


def result_row(r: IdentificationResult) -> Row:
    """The numeric columns of one result, each followed by ``<name>_std`` when the result
    carries that number's standard deviation (and ``<name>_lo``, ``<name>_hi`` when it carries
    a 95 % interval)."""
    values = _values(r)
    u = r.uncertainty
    # a check that could not fail (pass None: not checked) does not fail the file
    row: Row = {"checks_pass": all(c["pass"] is not False for c in r.checks().values())}
    for name, key, index, factor in COLUMNS:
        row[name] = float(np.asarray(values[key])[index]) * factor
        if u is not None and key in u.std:
            row[f"{name}_std"] = float(np.asarray(u.std[key])[index]) * abs(factor)
        if u is not None and key in u.ci95:
            lo, hi = sorted(float(v) * factor for v in np.asarray(u.ci95[key])[index])
            row[f"{name}_lo"], row[f"{name}_hi"] = lo, hi
    return row


def identify_file(path: str, settings: Settings, options: IdentifyOptions) -> Row:
    """One file's row: opened through the pipeline and identified as ``insitu identify`` does.

    Never raises for a bad file: its row has ``status`` ``"error"`` and the one-line reason.
    """
    t0 = time.perf_counter()
    row: Row = {"file": path}
    try:
        m = load(path, settings)
        result = fit(m, options)
    except Exception as err:  # a bad file must not stop the campaign: its row says why
        text = message_of(err)
        if not isinstance(err, ValueError | OSError | ArithmeticError):
            text = f"{type(err).__name__}: {text}"
        row.update(status="error", error=text)
    else:
        row.update(status="ok", error="", skipped_runs=m.provenance.skipped,
                   **result_row(result))
    row["seconds"] = time.perf_counter() - t0
    return row


def run_campaign(client: Client, paths: Sequence[str | Path], settings: Settings,
                 options: IdentifyOptions,
                 progress: Callable[[Row], None] | None = None) -> list[Row]:
    """:func:`identify_file` of each path on ``client``'s workers; rows in the paths' order.

    ``progress`` is called with each row as its file finishes.
    """
    futures = [client.submit(identify_file, str(p), settings, options, pure=False)
               for p in paths]
    index = {f.key: k for k, f in enumerate(futures)}
    rows: list[Row | None] = [None] * len(futures)
    try:
        for fut in as_completed(futures):
            k = index[fut.key]
            try:
                row = fut.result()
            except Exception as err:  # the worker itself died (memory, killed)
                row = {"file": str(paths[k]), "status": "error",
                       "error": f"worker lost: {message_of(err)}"}
            rows[k] = row
            if progress is not None:
                progress(row)
    finally:
        client.cancel(futures)
    return [r for r in rows if r is not None]


def columns_of(rows: Sequence[Row]) -> list[str]:
    """The table's columns: :data:`HEAD`, then each number followed by the spread columns any
    row has."""
    have = set().union(*(r.keys() for r in rows)) if rows else set()
    cols = list(HEAD)
    for name, *_ in COLUMNS:
        cols += [c for c in (name, f"{name}_std", f"{name}_lo", f"{name}_hi") if c in have]
    return cols


def write_tables(rows: Sequence[Row], out: Path, name: str = TABLE_NAME) -> list[Path]:
    """``name.csv``, ``name.parquet`` and ``name.html`` of the rows in folder ``out``
    (created); returns the three paths."""
    out.mkdir(parents=True, exist_ok=True)
    cols = columns_of(rows)
    paths = [out / f"{name}.csv", out / f"{name}.parquet", out / f"{name}.html"]
    with paths[0].open("w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=cols, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({c: ("" if r.get(c) is None else r.get(c)) for c in cols})
    schema = pa.schema([(c, pa.string() if c in ("file", "status", "error")
                         else pa.bool_() if c == "checks_pass"
                         else pa.int64() if c == "skipped_runs" else pa.float64())
                        for c in cols])
    pq.write_table(pa.Table.from_pylist([{c: r.get(c) for c in cols} for r in rows],
                                        schema=schema), paths[1])
    paths[2].write_text(_html(rows), encoding="utf-8")
    return paths


#: the HTML table's numbers: (heading, column, display factor, format)
_SHOWN = (("mass (kg)", "mass_kg", 1.0, ".3f"),
          *((f"CoG {a} (mm)", f"cog_{a}_m", 1e3, ".2f") for a in "xyz"),
          *((f"J_{n} CoG (kg m²)", f"J{n}_cog_kgm2", 1.0, ".4f") for n, *_ in _J),
          *((f"J_{k} (kg m²)", f"J{k}_principal_kgm2", 1.0, ".4f") for k in (1, 2, 3)),
          ("first mode (Hz)", "first_rigid_mode_hz", 1.0, ".2f"),
          ("last mode (Hz)", "last_rigid_mode_hz", 1.0, ".2f"))


def _cell(r: Row, col: str, factor: float, fmt: str) -> str:
    v = r.get(col)
    if v is None:
        return ""
    text = f"{v * factor:{fmt}}"
    if r.get(f"{col}_lo") is not None:
        text += f" [{r[f'{col}_lo'] * factor:{fmt}}, {r[f'{col}_hi'] * factor:{fmt}}]"
    elif r.get(f"{col}_std") is not None:
        text += " ± " + half_width(Z95 * r[f"{col}_std"] * factor)
    return text


def _html(rows: Sequence[Row]) -> str:
    ok = sum(r.get("status") == "ok" for r in rows)
    head = "".join(f"<th>{html.escape(h)}</th>"
                   for h in ("file", "status", *(s[0] for s in _SHOWN), "error"))
    body = []
    for r in rows:
        cls = "ok" if r.get("status") == "ok" else "bad"
        cells = [f"<td class=\"l\">{html.escape(str(r.get('file', '')))}</td>",
                 f"<td class=\"{cls}\">{html.escape(str(r.get('status', '')))}</td>",
                 *(f"<td>{html.escape(_cell(r, c, f, fmt))}</td>" for _, c, f, fmt in _SHOWN),
                 f"<td class=\"l\">{html.escape(str(r.get('error') or ''))}</td>"]
        body.append("<tr>" + "".join(cells) + "</tr>")
    return (
        "<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>Campaign</title><style>"
        "body{font-family:sans-serif;margin:2em;color:#222}"
        "table{border-collapse:collapse;font-size:.85em}"
        "td,th{border:1px solid #ccc;padding:3px 6px;text-align:right}"
        "th{background:#f0f0f0}td.l{text-align:left}"
        ".ok{color:#fff;background:#009E73}.bad{color:#fff;background:#D55E00}"
        "</style></head><body><h1>Campaign</h1>"
        f"<p>{len(rows)} files: {ok} identified, {len(rows) - ok} failed. Values ± 1.96 "
        "standard deviations (or [95 % interval]) where the result has them; products of "
        "inertia J_xy = ∫xy dm.</p>"
        f"<table><tr>{head}</tr>{''.join(body)}</table></body></html>")

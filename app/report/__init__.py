"""Test reports: the analysis of an FRF set (identification and checks), its figures and HTML.

:func:`app.report.analysis.analyse` runs everything a report shows on an :class:`FRFSet`;
:mod:`app.report.figures` draws it with pyqtgraph (the GUI's views use the same functions);
:func:`app.report.html.build_report` writes one self-contained HTML page with the figures
embedded as PNG.
"""

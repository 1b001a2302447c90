"""Everything the views and the report show about one measurement, computed in one call.

:func:`analyse` is pure computation (no Qt) so the GUI can run it in a worker thread and
``insitu report`` without a GUI. Failures of one part (an impossible geometry, a band outside
the data) are kept as one-line messages, never raised, so the other parts still show.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from processing.bootstrap import Progress
from processing.coherence import CoherenceGate, coherence_gate
from processing.data import FRFSet
from processing.geometry import DEFAULT_MAX_COND_T, GeometryReport, check_geometry
from processing.identify import IdentificationResult, IdentifyOptions, fit
from processing.measurement import Measurement
from processing.rigidity import RigidityCheck, rigidity_check

__all__ = ["Analysis", "analyse", "message_of"]


def message_of(err: BaseException) -> str:
    """One line for the operator: the exception's message, or its type when it has none."""
    text = " ".join(str(err).split())
    return text or type(err).__name__


@dataclass(frozen=True)
class Analysis:
    """Identification and checks of one measurement.

    Attributes
    ----------
    measurement : the measurement identified (:func:`processing.identify.fit`)
    frf : its FRFs on the lines above 0 Hz (accelerance, (m/s^2)/N)
    source : where they came from (file name or "acquisition")
    options : identification options used
    geometry : rank/condition of E and T, or None when the geometry itself is unusable
    result : identification result, or None when it failed (``error`` says why)
    rigidity : rigidity check, or None when it could not run (``rigidity_error`` says why)
    gate : coherence gate at the options' threshold, or None without coherence
    """

    measurement: Measurement
    frf: FRFSet
    source: str
    options: IdentifyOptions
    geometry: GeometryReport | None
    result: IdentificationResult | None
    error: str | None
    rigidity: RigidityCheck | None
    rigidity_error: str | None
    gate: CoherenceGate | None

    @property
    def positive_freq(self) -> NDArray[np.float64]:
        """The frequency lines the identification uses (all of ``frf``: f > 0), Hz."""
        return self.frf.freq

    def stiffness_freq(self) -> NDArray[np.float64]:
        """Lines of ``result.stiffness_per_line`` (the stiffness band), Hz."""
        if self.result is None:
            return np.zeros(0)
        f = self.positive_freq
        lo, hi = self.result.stiffness_band
        return f[(f >= lo) & (f <= hi)]

    def summary(self) -> str:
        """One line naming the data and the outcome."""
        n_r, n_e, n_f = self.frf.H.shape
        head = f"{self.source}: {n_r} response DOFs x {n_e} excitations, {n_f} lines"
        if self.result is None:
            return f"{head}; identification failed: {self.error}"
        return f"{head}; identified mass {self.result.properties.mass:.2f} kg"


def analyse(measurement: Measurement, options: IdentifyOptions | None = None,
            source: str = "", progress: Progress | None = None,
            result: IdentificationResult | None = None) -> Analysis:
    """Identify (:func:`processing.identify.fit`, as every view does) and check
    ``measurement``; never raises for bad data (messages instead).

    Parameters
    ----------
    measurement : the FRFs and their provenance (:func:`app.pipeline.load`)
    options : identification options (bands, method, physical constraint)
    source : label shown in views and reports
    progress : ``progress(done, total)`` of the bootstrap's resamples (:func:`fit`)
    result : ``fit(measurement, options)`` when already made (a live run's, as it stores it):
        taken instead of fitting again

    Examples
    --------
    >>> from hardware_mocks.benches import get_bench  # doctest: +SKIP
    >>> analyse(Measurement(get_bench("engine-rigid").frfset())).result  # doctest: +SKIP
    110.0...
    """
    opt = options or IdentifyOptions()
    frf = measurement.frf.select_lines()  # f > 0: accelerance and coherence defined
    geometry: GeometryReport | None
    try:
        geometry = check_geometry(frf.resp_xyz, frf.resp_dirs, frf.exc_xyz, frf.exc_dirs,
                                  max_cond_T=DEFAULT_MAX_COND_T)
    except ValueError as err:
        geometry = None
        geo_error: str | None = message_of(err)
    else:
        geo_error = None
    error: str | None = geo_error
    if geometry is not None and result is None:
        try:
            result = fit(measurement, opt, progress=progress)
        except (ValueError, ArithmeticError) as err:  # InputError, GeometryError, LinAlgError
            error = message_of(err)
    rigidity: RigidityCheck | None = None
    rigidity_error: str | None = None
    try:
        rigidity = rigidity_check(frf)
    except (ValueError, IndexError, ArithmeticError) as err:
        rigidity_error = message_of(err)
    gate = None
    if frf.coherence is not None:
        gate = coherence_gate(frf.coherence, frf.freq, opt.coherence_threshold)
    return Analysis(measurement, frf, source or measurement.source or "FRFs", opt, geometry,
                    result, error, rigidity, rigidity_error, gate)

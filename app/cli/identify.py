"""``insitu identify FILE.uff``: inertia parameters and mount-system stiffness from FRFs.

The file is a run file (``.h5``, written by ``insitu acquire``: its raw hits are
processed as ``insitu replay`` does), an HDF5 FRF file (``.h5``, written by
``insitu frf``; the two are told apart by the root attribute ``format``), or a UFF
file holding FRFs (dataset 58, function type 4) with geometry, or time records
(function type 1, one run per excitation, see ``insitu frf``), or a TDMS or MDF file of
time records with its channel map (``--channels``, docs/time-files.md): then the FRFs and
their coherence are computed first with the time-data options below, the coherence
gate keeps low-coherence lines out of the fit, and an exponential window's damping
is removed from C. Bad time runs are reported on one line each and left out; the
identification then runs on the others and the exit status is 2.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rich.console import Console

from app.cli.common import (
    VERB_HELP,
    UserError,
    check_output,
    check_range,
    fit_progress,
    write_output,
)
from app.cli.frf import add_processing_arguments, load_and_show, settings_from
from app.cli.summary import print_comparison, print_mount_system, print_result
from app.io.mounts import MountsFile, load_mounts
from app.pipeline import RUN_FILE, TIME_FORMATS, detect_format
from app.pipeline.settings import MAX_FMAX, TestUncertaintySettings
from app.report.mount_system import mount_system
from app.report.sources import plan_prediction
from processing.data import FRFSet
from processing.identify import IdentificationResult, IdentifyOptions, fit
from processing.montecarlo import StatedUncertainty
from processing.mounts import check_mounts

#: most rounds of point refinement (each a whole identification; they stop sooner when a
#: step moves no point by 0.01 mm or does not improve the fit)
MAX_REFINE_ROUNDS = 20


def add_parser(sub: Any) -> None:
    p = sub.add_parser("identify", help=VERB_HELP["identify"],
                       description=__doc__)
    p.add_argument("file", type=Path,
                   help="UFF file with geometry (15/2411) and FRFs or time records (58), "
                        "a TDMS or MDF file of time records (with --channels), "
                        "or a run file (.h5) written by insitu acquire, or an FRF file (.h5) "
                        "written by insitu frf")
    p.add_argument("--out", type=Path, help="write the result JSON here")
    p.add_argument("--mass-band", nargs=2, type=float, metavar=("LO", "HI"),
                   help="mass-line band in Hz (default: chosen from the data)")
    p.add_argument("--stiffness-band", nargs=2, type=float, metavar=("LO", "HI"),
                   help="stiffness band in Hz (default: chosen from the data)")
    p.add_argument("--physical", action="store_true",
                   help="constrain the inertia to physically consistent values")
    p.add_argument("--method", choices=("improved", "plain"), default="improved",
                   help="improved (default) or the article's plain method")
    p.add_argument("--stiffening", choices=("auto", "constant"), default="auto",
                   help="the mounts' stiffening with frequency: read from the stiffness lines "
                        "when they show one (auto, default) or K constant (docs/mounts.md)")
    p.add_argument("--channel-delays", choices=("auto", "off"), default="auto",
                   help="each response channel's delay against the force (channel skew): read "
                        "from the FRFs' phase and taken out when it shows (auto, default) or "
                        "FRFs as they are (docs/identification.md)")
    p.add_argument("--refine-points", type=int, default=0, metavar="N",
                   help="rounds of response-point location refinement from the data (e.g. 3; "
                        f"at most {MAX_REFINE_ROUNDS}; no bootstrap)")
    add_uncertainty_arguments(p)
    add_mount_arguments(p)
    add_processing_arguments(p.add_argument_group(
        "time data (UFF 58 time records, TDMS or MDF files instead of FRFs: FRFs are "
        "computed first)"))
    p.set_defaults(run=run)


def add_uncertainty_arguments(p: Any) -> None:
    """``--location-uncertainty``, ``--angle-uncertainty``, ``--gain-uncertainty``, ``--draws``,
    ``--no-uncertainty``."""
    g = p.add_argument_group(
        "uncertainty (standard deviations: the fit's covariance always; a Monte Carlo of the "
        "test's own uncertainties when stated; docs/uncertainty.md)")
    g.add_argument("--location-uncertainty", metavar="LEN",
                   help="standard deviation of each coordinate of each point, with its unit "
                        "(e.g. 3mm)")
    g.add_argument("--angle-uncertainty", metavar="ANGLE",
                   help="standard deviation of each sensor channel's direction, with its unit "
                        "(e.g. 2deg)")
    g.add_argument("--gain-uncertainty", metavar="REL",
                   help="standard deviation of each channel's gain (e.g. 2%%)")
    g.add_argument("--draws", type=int, metavar="N",
                   help="Monte Carlo draws of the stated uncertainties (default 1000)")
    g.add_argument("--bootstrap", type=int, metavar="N",
                   help="time data: resamples of the bootstrap over hits (hammer) or blocks "
                        "(shaker) (default 200 when every point has at least 3; 0: none)")
    g.add_argument("--no-uncertainty", action="store_true",
                   help="skip the uncertainty (no std in the result)")


def stated_from(args: argparse.Namespace) -> StatedUncertainty | None:
    """The stated test uncertainties of the command line (checked, one line each), or None."""
    s = TestUncertaintySettings(args.location_uncertainty, args.angle_uncertainty,
                                args.gain_uncertainty, args.draws)
    if not s.stated:
        return None
    if args.no_uncertainty:
        raise UserError("--no-uncertainty contradicts the stated uncertainties: drop one")
    if args.method == "plain":
        raise UserError("the Monte Carlo of stated uncertainties runs with the improved method: "
                        "drop --method plain or the uncertainty options")
    return StatedUncertainty(location=s.location, angle=s.angle, gain=s.gain,
                             draws=s.draws or 1000)


def add_mount_arguments(p: Any) -> None:
    """``--mounts``, ``--excitation-hz``, ``--loss-factor-hz`` (also used by ``report``)."""
    g = p.add_argument_group("mount system (modes are always reported)")
    g.add_argument("--mounts", type=Path, metavar="TOML",
                   help="mounts file (crank_axis, [[mount]] name/position/axes; "
                        "docs/conventions.md): individual mount rates and loss factors, "
                        "torque roll axis")
    g.add_argument("--excitation-hz", type=float, metavar="F",
                   help="excitation frequency (e.g. idle firing order), Hz: each mode's "
                        "frequency ratio, isolation margin (ratio / sqrt 2) and transmissibility")
    g.add_argument("--loss-factor-hz", type=float, metavar="F",
                   help="frequency of the viscous part of the mounts' loss factors "
                        "(d + 2 pi f c) / k, Hz (default: geometric mean of the rigid-body mode "
                        "frequencies); a structural (hysteretic) part d / k needs none")


def mounts_from(args: argparse.Namespace) -> MountsFile | None:
    """The mounts file, validated and checked for identifiability before any numerics."""
    check_range("--excitation-hz", args.excitation_hz, 0, MAX_FMAX, "Hz", above=True)
    check_range("--loss-factor-hz", args.loss_factor_hz, 0, MAX_FMAX, "Hz", above=True)
    if args.mounts is None:
        return None
    mounts = load_mounts(args.mounts)
    check_mounts(mounts.mounts)  # refuses (one line) when no rate can be determined
    return mounts


def bootstrap_from(args: argparse.Namespace) -> int | None:
    """``--bootstrap N`` checked (one line): None (the default rule), 0 (none) or N >= 2."""
    n = getattr(args, "bootstrap", None)
    if n is None:
        return None
    if n < 0 or n == 1:
        raise UserError(f"--bootstrap must be 0 (none) or at least 2 resamples, got {n}")
    if n > 100_000:
        raise UserError(f"--bootstrap {n} is more resamples than any test needs: give at most "
                        "100000 (200 is the default)")
    if n and args.no_uncertainty:
        raise UserError("--no-uncertainty contradicts --bootstrap: drop one")
    return int(n)


def options_from(args: argparse.Namespace, stated: StatedUncertainty | None) -> IdentifyOptions:
    """The user's identification choices of the command line (checked, one line each)."""
    check_range("--refine-points", args.refine_points, 0, MAX_REFINE_ROUNDS, "rounds")
    bands = {flag: band_from(flag, b) for flag, b in (("--mass-band", args.mass_band),
                                                      ("--stiffness-band", args.stiffness_band))}
    bootstrap = bootstrap_from(args)
    if args.refine_points and bootstrap:
        raise UserError("--refine-points runs no bootstrap (each round is one fit): drop "
                        "--bootstrap or --refine-points")
    return IdentifyOptions(
        method=args.method,
        stiffening=args.stiffening,
        channel_delays=args.channel_delays,
        mass_band=bands["--mass-band"],
        stiffness_band=bands["--stiffness-band"],
        physical=args.physical,
        refine_points=args.refine_points,
        coherence_threshold=args.coherence,
        uncertainty=not args.no_uncertainty,
        stated=stated,
        bootstrap=bootstrap,
    )


def band_from(flag: str, band: list[float] | None) -> tuple[float, float] | None:
    """``--mass-band LO HI`` or ``--stiffness-band LO HI`` checked: 0 <= LO < HI, finite."""
    if band is None:
        return None
    lo, hi = band
    check_range(flag, lo, 0, MAX_FMAX, "Hz")
    check_range(flag, hi, 0, MAX_FMAX, "Hz", above=True)
    if not lo < hi:
        raise UserError(f"{flag} {lo:g} {hi:g}: give the lower edge first (LO < HI, Hz)")
    return float(lo), float(hi)


@dataclass(frozen=True)
class _Mounts:
    """The mount-system options: the mounts table (or None) and the two frequencies."""

    table: MountsFile | None
    excitation_hz: float | None
    loss_factor_hz: float | None


def run(args: argparse.Namespace) -> int:
    options = options_from(args, stated_from(args))  # every option checked before any file
    settings = settings_from(args)
    if args.out is not None:
        check_output(args.out, inputs=(args.file,))
    mounts = _Mounts(mounts_from(args), args.excitation_hz, args.loss_factor_hz)
    fmt = detect_format(args.file)
    if fmt in TIME_FORMATS:
        how = f"{args.excitation} excitation" if args.excitation else "settings from the data"
        print(f"{args.file}: time records; computing FRFs ({how})")
    m = load_and_show(args.file, args, settings, fmt)
    stored = None
    if fmt == RUN_FILE and mounts.table is None:
        from app.io.runfile import run_mounts  # HDF5: for run files only

        stored = run_mounts(args.file)
    if stored is not None:
        print(f"{args.file}: using the run file's mounts table ({len(stored.mounts)} mounts)")
        check_mounts(stored.mounts)
        mounts = dataclasses.replace(mounts, table=stored)
    prediction = plan_prediction(args.file, fmt)  # the run's plan's, by insitu plan
    with fit_progress() as progress:
        result = fit(m, options, progress=progress)
    _report(args.file, args.out, m.frf, result, mounts, prediction)
    return 2 if m.provenance.skipped else 0


def _report(path: Path, out: Path | None, frf: FRFSet, result: IdentificationResult,
            mounts: _Mounts, prediction: dict[str, Any] | None = None) -> None:
    console = Console()
    console.print(f"[bold]{path}[/bold]: {frf.H.shape[0]} response DOFs x "
                  f"{frf.H.shape[1]} excitations, {frf.freq.size} lines "
                  f"{frf.freq[0]:g}-{frf.freq[-1]:g} Hz")
    print_result(result, console)
    if prediction is not None:
        print_comparison(prediction, result.uncertainty, console)
    ms = mount_system(result, mounts.table, mounts.excitation_hz, mounts.loss_factor_hz)
    print_mount_system(ms, console, spreads=result.uncertainty is None)
    if out:
        write_output(out, json.dumps({**result.to_json(), **ms.to_json()}, indent=2))
        console.print(f"result written to {out}")

"""The terminal summary shows each identified number's 95 % spread and the largest
contributions when the result carries an uncertainty, and is unchanged without one."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from rich.console import Console

from app.cli.summary import print_result
from hardware_mocks.benches import get_bench
from processing.identify import IdentificationResult, IdentifyOptions, identify
from processing.results import Contribution, Uncertainty


def with_uncertainty(r: IdentificationResult) -> IdentificationResult:
    """``r`` with std of 1 % of each value plus a distinct offset per entry, an asymmetric
    95 % interval for the inertia about the CoG, two sources and three contributions."""
    p = r.properties
    values = {"mass": p.mass, "cog": p.cog, "inertia_cog": p.inertia_cog,
              "inertia_origin": p.inertia_origin, "principal_moments": p.principal_moments,
              "stiffness": r.K, "damping": r.C, "rigid_modes_hz": r.rigid_modes_hz}
    std = {k: 0.01 * np.abs(v) + 1e-3 * (1 + np.arange(np.size(v))).reshape(np.shape(v))
           for k, v in values.items()}
    J = p.inertia_cog
    ci = np.stack([J - 2 * std["inertia_cog"], J + 3 * std["inertia_cog"]], axis=-1)
    u = Uncertainty(std=std, ci95={"inertia_cog": ci},
                    sources=("fit covariance (FRF noise)",
                             "Monte Carlo of point locations ± 2 mm, 200 draws"),
                    contributions=(Contribution("cog z", "point 3 location", 0.7),
                                   Contribution("inertia_cog xy", "fit (noise)", 0.55),
                                   Contribution("mass", "gain of channel 4", 0.4)))
    return replace(r, uncertainty=u)


@pytest.fixture(scope="module")
def result() -> IdentificationResult:
    return identify(get_bench("engine-rigid").frfset(noise=0.01, seed=1),
                    IdentifyOptions(uncertainty=False))


def _text(r: IdentificationResult) -> str:
    con = Console(record=True, width=240)
    print_result(r, con)
    return con.export_text()


def _row(text: str, start: str) -> str:
    rows = [ln for ln in text.splitlines() if ln.startswith("│ " + start)]
    assert len(rows) == 1, (start, rows)
    return rows[0]


def test_terminal_shows_spreads_and_contributions(result: IdentificationResult) -> None:
    r = with_uncertainty(result)
    u = r.uncertainty
    assert u is not None
    text = _text(r)
    p = r.properties
    assert f"± {1.96 * u.std['mass']:.2g}" in _row(text, "mass ")
    z = _row(text, "z_c ")
    assert f"{p.cog[2] * 1e3:.4g}" in z and f"± {1.96 * u.std['cog'][2] * 1e3:.2g}" in z
    jxy = _row(text, "J_xy (O)")
    assert f"{-p.inertia_origin[0, 1]:.4g}" in jxy
    assert f"± {1.96 * u.std['inertia_origin'][0, 1]:.2g}" in jxy
    pm = _row(text, "principal moments")
    assert all(f"± {1.96 * s:.2g}" in pm for s in u.std["principal_moments"])
    K, sK = r.K, u.std["stiffness"]
    assert f"{K[2, 2]:.4g} ± {1.96 * sK[2, 2]:.2g}" in text
    C, sC = r.C, u.std["damping"]
    assert f"{C[5, 0]:.4g} ± {1.96 * sC[5, 0]:.2g}" in text
    f, sf = r.rigid_modes_hz, u.std["rigid_modes_hz"]
    assert f"rigid-body modes {f[0]:.1f} ± {1.96 * sf[0]:.2g}, {f[1]:.1f} ±" in text
    assert ("fit covariance (FRF noise); Monte Carlo of point locations ± 2 mm, 200 draws"
            in text)
    block = text[text.index("Largest contributions"):].splitlines()[1:4]
    assert [b.strip() for b in block] == ["CoG z: 70 % from point 3 location",
                                          "J_xy about the CoG: 55 % from fit (noise)",
                                          "mass: 40 % from gain of channel 4"]


def test_terminal_unchanged_without_uncertainty(result: IdentificationResult) -> None:
    text = _text(result)
    assert result.uncertainty is None
    assert "±" not in text and "95 %" not in text and "contributions" not in text
    assert f"{result.properties.mass:.4g}" in _row(text, "mass ")
    # the same result with an uncertainty differs only by the spreads and the block
    with_u = _text(with_uncertainty(result))
    assert with_u != text and "Largest contributions" in with_u

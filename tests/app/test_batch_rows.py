"""A campaign row carries each number's standard deviation (and 95 % interval) when the result
has them, and the three tables keep them."""

from __future__ import annotations

import csv
from dataclasses import replace
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from app.batch.campaign import result_row, write_tables
from hardware_mocks.benches import get_bench
from processing.identify import IdentifyOptions, identify
from processing.results import Uncertainty


def test_rows_and_tables_carry_the_uncertainty(tmp_path: Path) -> None:
    f = get_bench("engine-rigid").frfset(noise=0.01, seed=3)
    r = identify(replace(f, freq=f.freq[::4], H=f.H[:, :, ::4]),
                 IdentifyOptions(uncertainty=False))
    p = r.properties
    std = {"mass": np.array(0.2), "cog": np.array([1e-3, 2e-3, 3e-3]),
           "inertia_cog": np.full((3, 3), 0.01), "rigid_modes_hz": np.arange(1.0, 7.0) / 10}
    J = p.inertia_cog
    u = Uncertainty(std=std, ci95={"inertia_cog": np.stack([J - 0.02, J + 0.05], axis=-1)})
    plain, row = result_row(r), result_row(replace(r, uncertainty=u))
    assert not any(k.endswith(("_std", "_lo", "_hi")) for k in plain)
    assert row["mass_kg"] == pytest.approx(p.mass) and row["mass_kg_std"] == 0.2
    assert row["cog_z_m_std"] == 3e-3 and "inertia" not in row
    assert row["last_rigid_mode_hz"] == pytest.approx(r.rigid_modes_hz[5])
    assert row["last_rigid_mode_hz_std"] == pytest.approx(0.6)
    # J_xy = -J[0, 1]: the interval's ends change sign and swap
    assert row["Jxy_cog_kgm2"] == pytest.approx(-J[0, 1])
    assert row["Jxy_cog_kgm2_lo"] == pytest.approx(-J[0, 1] - 0.05)
    assert row["Jxy_cog_kgm2_hi"] == pytest.approx(-J[0, 1] + 0.02)
    assert "Jxx_O_kgm2_std" not in row and "J1_principal_kgm2_std" not in row
    rows = [{"file": "a.uff", "status": "ok", "error": "", "seconds": 1.0, "skipped_runs": 0,
             **row},
            {"file": "b.uff", "status": "error", "error": "bad", "seconds": 0.1}]
    csv_path, parquet, page = write_tables(rows, tmp_path / "out")
    with csv_path.open(newline="") as fh:
        head = next(csv.reader(fh))
    assert head.index("mass_kg_std") == head.index("mass_kg") + 1
    assert head[head.index("Jxy_cog_kgm2") + 1:head.index("Jxy_cog_kgm2") + 4] == [
        "Jxy_cog_kgm2_std", "Jxy_cog_kgm2_lo", "Jxy_cog_kgm2_hi"]
    table = pq.read_table(parquet).to_pylist()
    assert table[0]["cog_y_m_std"] == 2e-3 and table[1]["cog_y_m_std"] is None
    html = page.read_text()
    assert f"<td>{p.mass:.3f} ± {1.96 * 0.2:.2g}</td>" in html
    assert f"<td>{p.cog[2] * 1e3:.2f} ± {1.96 * 3:.2g}</td>" in html
    lo, hi = (-J[0, 1] - 0.05, -J[0, 1] + 0.02)
    assert f"<td>{-J[0, 1]:.4f} [{lo:.4f}, {hi:.4f}]</td>" in html

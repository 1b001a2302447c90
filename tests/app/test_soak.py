"""Two minutes of the soak test (benchmarks/soak.py): faults at random, no accepted hit lost."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_two_minute_soak(tmp_path: Path) -> None:
    out = tmp_path / "soak.json"
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "soak.py"), "--minutes",
                           "2", "--seed", "3", "--json", str(out)], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)
    report = json.loads(out.read_text())
    assert report["crashes"] == [], proc.stdout[-3000:]
    assert report["accepted_lost"] == 0
    assert report["accepted"] >= 20 and report["records"] >= report["accepted"]
    assert sum(report["faults"].values()) >= 3  # faults were injected
    assert report["rss_growth_mb"] < 50
    assert proc.returncode == 0

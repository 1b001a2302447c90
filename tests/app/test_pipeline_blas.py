"""A time UFF is loaded on one BLAS thread, whatever the caller set: the hit processing's
least squares (the decay fits) are small, and beside a busy process a second OpenBLAS
thread made a hammer file's load many times slower."""

from __future__ import annotations

from pathlib import Path

import pytest
from threadpoolctl import threadpool_info, threadpool_limits

import processing.impact as impact_module
from app.pipeline import load
from hardware_mocks.reference.scenarios import ScenarioSpec, build_scenario
from hardware_mocks.reference.timedata import HammerSpec, hammer_test, write_uff


def _blas_threads() -> set[int]:
    return {p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"}


def test_a_hammer_file_is_loaded_on_one_blas_thread(tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "hammer.uff"
    scenario = build_scenario(ScenarioSpec(seed=9411, n_forces=6))
    write_uff(hammer_test(scenario, HammerSpec(9411, hits=1)), path)
    seen: list[set[int]] = []
    decay = impact_module.free_decay

    def probe(*args, **kwargs):  # type: ignore[no-untyped-def]
        seen.append(_blas_threads())
        return decay(*args, **kwargs)

    monkeypatch.setattr(impact_module, "free_decay", probe)
    with threadpool_limits(2, user_api="blas"):
        m = load(path)
        assert _blas_threads() == {2}  # the caller's setting, restored
    assert m.frf.H.shape[1] == 6
    assert seen and all(s == {1} for s in seen), seen

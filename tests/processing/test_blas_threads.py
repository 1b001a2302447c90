"""The fit runs its small matrices on one BLAS thread, whatever the caller set: a second
thread gains nothing there and, beside another busy process, its spinning made a fit 30
times slower."""

from __future__ import annotations

import pytest
from threadpoolctl import threadpool_info, threadpool_limits

import processing.identify as identify_module
from hardware_mocks.benches import get_bench
from processing.identify import identify


def _blas_threads() -> list[int]:
    return [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]


def test_the_fit_uses_one_blas_thread_and_restores_the_callers(
        monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[list[int]] = []
    solve = identify_module.solve

    def probe(*args, **kwargs):  # type: ignore[no-untyped-def]
        seen.append(_blas_threads())
        return solve(*args, **kwargs)

    monkeypatch.setattr(identify_module, "solve", probe)
    frf = get_bench("engine-rigid").frfset(noise=0.01, seed=41)
    with threadpool_limits(2, user_api="blas"):
        before = _blas_threads()
        result = identify(frf)
        after = _blas_threads()
    assert before and set(before) == {2}, "no BLAS library found to limit"
    assert seen and all(set(s) == {1} for s in seen), seen
    assert after == before
    assert abs(result.properties.mass - get_bench("engine-rigid").model.mass) < 1.0

"""K and C are fitted symmetric: their standard deviations are those of the symmetric
estimates, one per pair of mirrored entries."""

from __future__ import annotations

import numpy as np
from numpy.testing import assert_allclose

from hardware_mocks.benches import get_bench
from processing.identify import identify


def test_the_spreads_of_k_and_c_are_symmetric_like_k_and_c() -> None:
    # the FRFs of `insitu identify engine.uff`: K[x, y] had 95 % spreads 2.7e3 and K[y, x]
    # 2.0e3 (C[x, y] 21 and C[y, x] 13) for one symmetric estimate
    res = identify(get_bench("engine").frfset(noise=0.02, seed=9301))
    u = res.uncertainty
    assert u is not None
    for key, A in (("stiffness", res.K), ("damping", res.C)):
        assert_allclose(A, A.T, rtol=0, atol=0)
        assert_allclose(u.std[key], u.std[key].T, rtol=1e-12, atol=0)
    # the joint covariance too: vec K and vec K^T are the same numbers
    cov = u.covariance
    assert cov is not None
    swap = np.arange(36).reshape(6, 6).T.ravel()
    for lo in (10, 46):
        block = cov[lo:lo + 36, lo:lo + 36]
        assert_allclose(block, block[np.ix_(swap, swap)], rtol=1e-9, atol=1e-9 * block.max())


def test_the_symmetric_spread_is_that_of_the_symmetric_part() -> None:
    from processing.uncertainty import symmetrised

    rng = np.random.default_rng(3)
    A = rng.standard_normal((82, 82))
    cov = A @ A.T
    out = symmetrised(cov)
    i, j = 10 + 0 * 6 + 1, 10 + 1 * 6 + 0  # K[x, y] and K[y, x]
    want = (cov[i, i] + cov[j, j] + 2 * cov[i, j]) / 4
    assert_allclose([out[i, i], out[j, j]], [want, want], rtol=1e-12)
    assert_allclose(out[:10, :10], cov[:10, :10], rtol=0)  # theta untouched


"""Force and exponential windows; exact removal of the damping the exponential window adds."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal
from numpy.testing import assert_allclose, assert_array_equal

from hardware_mocks.benches import get_bench
from processing.windows import (
    correct_dynamic_stiffness,
    correct_modal_damping,
    exponential_tau,
    exponential_window,
    force_window,
    window_samples,
)


def test_force_window_shapes():
    w = force_window(10, stop=[3, 5], taper=[2, 0], start=[0, 1])
    assert w.shape == (2, 10)
    assert_allclose(w[0], [1, 1, 1, 0.75, 0.25, 0, 0, 0, 0, 0])
    assert_allclose(w[1], [0, 1, 1, 1, 1, 0, 0, 0, 0, 0])
    with pytest.raises(ValueError, match="taper"):
        force_window(10, stop=2, taper=-1)


def test_exponential_window_and_tau():
    tau = exponential_tau(2.0, 0.01)
    w = exponential_window(2049, 1024.0, tau)
    assert w[0] == 1.0 and w[-1] == pytest.approx(0.01)
    with pytest.raises(ValueError, match="positive"):
        exponential_window(10, 1.0, 0.0)


def test_modal_damping_correction_moves_the_pole_back():
    f, z, tau = 12.0, 0.03, 0.5
    wn = 2 * np.pi * f
    pole = -z * wn + 1j * wn * np.sqrt(1 - z**2) - 1 / tau  # what the windowed data show
    f_m, z_m = abs(pole) / (2 * np.pi), -pole.real / abs(pole)
    assert z_m == pytest.approx(z + 1 / (tau * wn), rel=0.01)  # first order
    f_c, z_c = correct_modal_damping(f_m, z_m, tau)
    assert f_c == pytest.approx(f, rel=1e-12) and z_c == pytest.approx(z, rel=1e-10)


def test_dynamic_stiffness_correction_recovers_k_and_c():
    model = get_bench("engine").model
    tau = 0.2
    freq = np.linspace(1.0, 40.0, 60)
    s = 2j * np.pi * freq + 1 / tau
    # windowed accelerance at O for unit generalised forces (T = I): X_w = s^2 Z(s)^-1
    Z = model.K[None] + s[:, None, None] * model.C[None] + (s**2)[:, None, None] * model.M[None]
    Xw = (s**2)[:, None, None] * np.linalg.inv(Z)
    w = 2 * np.pi * freq
    # the article's eq. 14 with T = I: K* = w^2 (M X - I) X^-1
    Km = (w**2)[:, None, None] * (model.M[None] - np.linalg.inv(Xw))
    K_true = model.K[None] + 1j * w[:, None, None] * model.C[None]
    assert np.abs(Km - K_true).max() > 0.1 * np.abs(model.K).max()  # the window matters
    Kc = correct_dynamic_stiffness(np.moveaxis(Km, 0, -1), freq, tau)
    assert_allclose(np.moveaxis(Kc, -1, 0), K_true, atol=1e-6 * np.abs(model.K).max())


def test_a_windowed_fit_states_its_window_in_the_damping_note_not_as_a_warning():
    """The window's damping taken off C is what the processing does, not a problem: the
    damping model's note names the window, no warning; the fit recovers the model's truth
    from FRFs the window turned into H(jw + 1/tau)."""
    import dataclasses

    from hardware_mocks.signals import frf_laplace
    from processing.identify import fit
    from processing.inertia import inertia_properties
    from processing.measurement import Measurement, Provenance

    bench, tau = get_bench("engine-rigid"), 0.4
    g = bench.geometry
    H = frf_laplace(bench.model, 2j * np.pi * bench.freq + 1 / tau, g.coordinates(bench.resp_nodes),
                    bench.resp_dirs, g.coordinates(bench.exc_nodes), bench.exc_dirs)
    r = fit(Measurement(dataclasses.replace(bench.frfset(), H=H),
                        Provenance(exponential_tau=tau)))
    assert r.warnings == ()
    assert "exponential window (tau = 0.4 s; the damping it added was removed from C" in (
        r.damping_note)
    assert r.properties.mass == pytest.approx(inertia_properties(bench.model.theta).mass,
                                              rel=1e-4)
    assert_allclose(np.diag(r.C), np.diag(bench.model.C), rtol=0.01)


@pytest.mark.parametrize("name", ["hann", "han", "hamming", "hamm", "ham", "blackman", "black",
                                  "blk", "flattop", "flat", "flt", "boxcar", "box", "ones",
                                  "rect", "rectangular"])
@pytest.mark.parametrize("n", [1, 2, 7, 256, 2049])
def test_cosine_windows_are_scipys_bit_for_bit(name, n):
    assert_array_equal(window_samples(name, n), scipy.signal.get_window(name, n))


def test_other_windows_come_from_scipy():
    assert_array_equal(window_samples(("tukey", 0.3), 64),
                       scipy.signal.get_window(("tukey", 0.3), 64))
    with pytest.raises(ValueError):
        window_samples("no-such-window", 64)

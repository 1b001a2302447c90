"""Rigidity check on the bench model: rigid engine, engine with an elastic mode, bad geometry."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from hardware_mocks.benches import get_bench
from processing.geometry import GeometryError
from processing.rigidity import _rigid_band, rigidity_check


def test_rigid_body_is_predicted_exactly():
    rc = rigidity_check(get_bench("engine-rigid").frfset())
    assert np.nanmax(rc.error) < 1e-10
    assert rc.band == (0.125, 128.0)
    assert rc.passed and "rigid from 0.125 to 128 Hz" in rc.summary()


def test_elastic_mode_ends_the_rigid_band_below_it():
    bench = get_bench("engine")  # first elastic mode at 118.5 Hz
    frfs = bench.frfset()
    rc = rigidity_check(frfs)
    assert rc.band is not None and 95.0 < rc.band[1] < 118.5
    at = np.argmin(np.abs(rc.freq - 118.5))
    assert rc.worst[at] > 0.1 and rc.overall[at] > 0.1
    low = rc.freq < 60
    assert np.nanmax(rc.error[:, low]) < 0.01
    assert rc.predicted.shape == frfs.H.shape
    assert rc.nodes.tolist() == [1, 2, 3, 4]


def test_noise_and_a_wrong_coordinate_show():
    bench = get_bench("block")
    noisy = rigidity_check(bench.frfset(noise=0.02), sustain=5, fmin=10.0)
    assert noisy.band is not None and noisy.band[0] >= 10.0
    assert np.nanmedian(noisy.overall[(noisy.freq > 20) & (noisy.freq < 150)]) < 0.05
    frfs = bench.frfset()
    xyz = frfs.geometry.xyz.copy()
    xyz[list(frfs.geometry.node_ids).index(2)] += [0.05, 0.0, 0.0]  # 5 cm off
    moved = rigidity_check(dataclasses.replace(
        frfs, geometry=dataclasses.replace(frfs.geometry, xyz=xyz)))
    assert moved.band is None or moved.band[1] < 20.0


def test_needs_three_non_collinear_nodes():
    frfs = get_bench("engine").frfset()
    keep = frfs.resp_nodes != 4
    keep &= frfs.resp_nodes != 3
    two = dataclasses.replace(frfs, H=frfs.H[keep], resp_nodes=frfs.resp_nodes[keep],
                              resp_dirs=frfs.resp_dirs[keep], coherence=None)
    with pytest.raises(GeometryError, match="at least 3 response nodes"):
        rigidity_check(two)
    xyz = frfs.geometry.xyz.copy()
    ids = list(frfs.geometry.node_ids)
    xyz[ids.index(3)] = 0.5 * (xyz[ids.index(1)] + xyz[ids.index(2)])  # 1, 2, 3 on a line
    line = dataclasses.replace(frfs, geometry=dataclasses.replace(frfs.geometry, xyz=xyz))
    with pytest.raises(GeometryError, match="other than node 4"):
        rigidity_check(line)


def test_band_needs_a_sustained_stretch():
    freq = np.arange(10.0)
    err = np.array([0.01, 0.2, 0.01, 0.01, 0.2, 0.2, 0.2, 0.01, 0.3, 0.3])
    ok = np.ones(10, bool)
    assert _rigid_band(freq, err, ok, 0.1, 3) == (0.0, 3.0)
    assert _rigid_band(freq, err, ok, 0.1, 1) == (0.0, 0.0)
    assert _rigid_band(freq, err, ok, 0.5, 3) == (0.0, 9.0)
    assert _rigid_band(freq, err + 1, ok, 0.1, 3) is None

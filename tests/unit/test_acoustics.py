"""Acoustic link budget and connectivity, eqs. (22)-(26)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from auv_swarm.contract.acoustics import (
    fiedler_value,
    fiedler_value_3,
    laplacian_from_weights,
    snr_db,
    snr_db_cfg,
    snr_laplacian,
    snr_max_db,
    thorp_absorption_db_per_km,
    transmission_loss_db,
)
from auv_swarm.contract.config import ChannelConfig


def test_thorp_absorption_at_10_khz_by_hand() -> None:
    # f = 10 kHz, f^2 = 100:
    #   0.11 * 100 / 101     = 0.1089109
    #   44 * 100 / 4200      = 1.0476190
    #   2.75e-4 * 100        = 0.0275
    #   + 0.003              = 0.003
    #   alpha(10 kHz)        = 1.1870299 dB/km
    assert thorp_absorption_db_per_km(10.0) == pytest.approx(1.1870299, abs=1e-6)


def test_thorp_vectorised_and_rejects_negative_frequency() -> None:
    f = np.array([1.0, 10.0, 30.0])
    out = thorp_absorption_db_per_km(f)
    assert out.shape == (3,)
    assert out[1] == pytest.approx(thorp_absorption_db_per_km(10.0))
    assert np.all(np.diff(out) > 0.0)
    with pytest.raises(ValueError, match="f_khz"):
        thorp_absorption_db_per_km(-1.0)


def test_transmission_loss_at_1_km() -> None:
    # 20 log10(1000) = 60 dB spreading, plus 1 km * 1.1870299 dB/km absorption.
    assert transmission_loss_db(1000.0, 10.0) == pytest.approx(61.1870299, abs=1e-6)


def test_transmission_loss_clamps_range_below_one_metre() -> None:
    tl = transmission_loss_db(np.array([0.0, 0.5, 1.0]), 10.0)
    expected = 1.1870299e-3
    np.testing.assert_allclose(tl, [expected, expected, expected], rtol=1e-6)
    with pytest.raises(ValueError, match="range_m"):
        transmission_loss_db(-5.0, 10.0)


def test_snr_db_and_config_form() -> None:
    ch = ChannelConfig(source_level_db=186.0, noise_level_db=50.0, directivity_index_db=3.0, frequency_khz=10.0)
    expected = 186.0 - 61.1870299 - 50.0 + 3.0
    assert snr_db(1000.0, 186.0, 50.0, 3.0, 10.0) == pytest.approx(expected, abs=1e-6)
    assert snr_db_cfg(1000.0, ch) == pytest.approx(expected, abs=1e-6)
    assert snr_db_cfg(np.array([100.0, 1000.0]), ch).shape == (2,)


def test_snr_max_default_and_override() -> None:
    assert snr_max_db(ChannelConfig(source_level_db=186.0, noise_level_db=40.0, directivity_index_db=2.0)) == 148.0
    assert snr_max_db(ChannelConfig(snr_max_db=120.0)) == 120.0


def test_laplacian_from_weights_rows_sum_to_zero() -> None:
    w = np.array([[5.0, 1.0, 2.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    lap = laplacian_from_weights(w)
    np.testing.assert_allclose(lap, [[3.0, -1.0, -2.0], [-1.0, 1.0, 0.0], [-2.0, 0.0, 2.0]])
    with pytest.raises(ValueError, match="weights"):
        laplacian_from_weights(-w)
    with pytest.raises(ValueError, match="weights"):
        laplacian_from_weights(np.ones((2, 3)))


def test_snr_laplacian_matches_eqs_25_26() -> None:
    ch = ChannelConfig(noise_level_db=50.0, detection_threshold_db=10.0)
    pos = np.array([[0.0, 0.0], [1000.0, 0.0], [0.0, 2000.0]])
    lap = snr_laplacian(pos, ch)
    rho_m = 186.0 - 50.0
    d = np.array(
        [[0.0, 1000.0, 2000.0], [1000.0, 0.0, math.hypot(1000.0, 2000.0)], [2000.0, math.hypot(1000.0, 2000.0), 0.0]]
    )
    w = (186.0 - 50.0 - transmission_loss_db(d, 10.0)) / rho_m
    np.fill_diagonal(w, 0.0)
    np.testing.assert_allclose(lap, np.diag(w.sum(axis=1)) - w, rtol=1e-12)
    np.testing.assert_allclose(lap.sum(axis=1), 0.0, atol=1e-12)
    assert np.all(np.diag(lap) > 0.0)


def test_snr_laplacian_drops_links_below_threshold() -> None:
    # SNR at 1 km with SL 186, NL 120: 186 - 61.19 - 120 = 4.81 dB < DT = 10 dB: no link.
    ch = ChannelConfig(noise_level_db=120.0, detection_threshold_db=10.0)
    lap = snr_laplacian(np.array([[0.0, 0.0], [1000.0, 0.0]]), ch)
    np.testing.assert_array_equal(lap, np.zeros((2, 2)))
    assert fiedler_value(lap) == 0.0


def test_snr_laplacian_treats_non_positive_snr_as_absent_even_with_negative_threshold() -> None:
    ch = ChannelConfig(noise_level_db=130.0, detection_threshold_db=-50.0)
    # rho(1 km) = 186 - 61.19 - 130 < 0 dB: absent although above DT.
    lap = snr_laplacian(np.array([[0.0, 0.0], [1000.0, 0.0]]), ch)
    np.testing.assert_array_equal(lap, np.zeros((2, 2)))


def test_snr_laplacian_batched_and_coincident_nodes() -> None:
    ch = ChannelConfig()
    pos = np.zeros((4, 3, 2))
    lap = snr_laplacian(pos, ch)
    assert lap.shape == (4, 3, 3)
    assert np.all(np.isfinite(lap))
    assert fiedler_value(lap[0]) > 0.0


def _random_connected_weights(rng: np.random.Generator, n: int) -> np.ndarray:
    w = np.triu(rng.uniform(0.1, 1.0, (n, n)), 1)
    return w + w.T


@pytest.mark.parametrize("n", [2, 3, 4, 5, 6])
def test_fiedler_positive_when_connected(n: int) -> None:
    rng = np.random.default_rng(n)
    w = _random_connected_weights(rng, n)
    lam = fiedler_value(laplacian_from_weights(w))
    assert lam > 0.0
    assert lam == pytest.approx(np.linalg.eigvalsh(laplacian_from_weights(w))[1])


@pytest.mark.parametrize(("n", "components"), [(n, c) for n in range(2, 7) for c in (2, 3) if c <= n])
def test_fiedler_exactly_zero_when_disconnected(n: int, components: int) -> None:
    rng = np.random.default_rng(100 * n + components)
    labels = np.arange(n) % components
    w = _random_connected_weights(rng, n) * (labels[:, None] == labels[None, :])
    lap = laplacian_from_weights(w)
    assert fiedler_value(lap) == 0.0


def test_fiedler_single_node_and_path_graph() -> None:
    assert fiedler_value(np.zeros((1, 1))) == 0.0
    # Unit-weight path on 3 nodes: eigenvalues 0, 1, 3.
    path = laplacian_from_weights(np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 1.0], [0.0, 1.0, 0.0]]))
    assert fiedler_value(path) == pytest.approx(1.0)


def test_fiedler_rejects_bad_input() -> None:
    with pytest.raises(ValueError, match="square"):
        fiedler_value(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="symmetric"):
        fiedler_value(np.array([[1.0, -1.0], [0.0, 0.0]]))
    with pytest.raises(ValueError, match="finite"):
        fiedler_value(np.array([[np.nan, 0.0], [0.0, 0.0]]))


def test_fiedler_3_closed_form_equals_eigenvalue() -> None:
    rng = np.random.default_rng(7)
    w = rng.uniform(0.0, 2.0, (500, 3))
    w[::5, 0] = 0.0
    w[::7, 1] = 0.0
    w[::11, [0, 2]] = 0.0
    closed = fiedler_value_3(w[:, 0], w[:, 1], w[:, 2])
    assert closed.shape == (500,)
    for (a, b, c), lam in zip(w, closed, strict=True):
        lap = laplacian_from_weights(np.array([[0.0, a, b], [a, 0.0, c], [b, c, 0.0]]))
        assert lam == pytest.approx(fiedler_value(lap), rel=1e-9, abs=1e-12)


def test_fiedler_3_disconnected_and_degenerate() -> None:
    assert fiedler_value_3(0.0, 0.0, 0.7) == 0.0
    assert fiedler_value_3(0.0, 0.0, 0.0) == 0.0
    assert fiedler_value_3(1.0, 1.0, 1.0) == pytest.approx(3.0)
    with pytest.raises(ValueError, match="w12"):
        fiedler_value_3(-1.0, 0.0, 0.0)

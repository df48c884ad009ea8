"""Match measures and node costs against direct per-window computations."""

from __future__ import annotations

import numpy as np
import pytest

from mrfpe.brdf.stereo import match as M


def _ncc_direct(A, B, eps):
    """6.36 with the variance regulariser, one window pair (h, w, C), written out."""
    a = A - A.mean(axis=(0, 1))
    b = B - B.mean(axis=(0, 1))
    n = A.shape[0] * A.shape[1]
    cov = (a * b).sum() / n
    va, vb = (a * a).sum() / n, (b * b).sum() / n
    return cov / np.sqrt((va + eps) * (vb + eps))


def _pair(rng, shape=(12, 20, 3)):
    left = rng.random(shape)
    right = rng.random(shape)
    return left, right


@pytest.mark.parametrize("channels", [1, 3])
def test_ncc_matches_direct_windows(channels):
    rng = np.random.default_rng(0)
    left, right = _pair(rng, (12, 20, channels))
    disp = np.array([0.0, 1.0, 3.0, 5.0])
    eps = 1e-3
    m, valid = M.match_measure(left, right, disp, window=3, match="ncc", eps=eps)
    assert m.shape == (12, 20, 4) and valid.shape == (12, 20, 4)
    for r in (2, 5, 9):
        for c in (7, 11, 17):
            for k, d in enumerate(disp.astype(int)):
                A = left[r - 1:r + 2, c - 1:c + 2]
                B = right[r - 1:r + 2, c - d - 1:c - d + 2]
                expect = (np.clip(_ncc_direct(A, B, eps), -1, 1) + 1) / 2  # 6.37
                assert m[r, c, k] == pytest.approx(expect, abs=1e-10)


def test_ssd_matches_direct_windows():
    rng = np.random.default_rng(1)
    left, right = _pair(rng)
    disp = np.array([0.0, 2.0, 4.0])
    m, _ = M.match_measure(left, right, disp, window=5, match="ssd")
    for r, c in ((3, 8), (6, 12), (8, 16)):
        for k, d in enumerate(disp.astype(int)):
            A = left[r - 2:r + 3, c - 2:c + 3]
            B = right[r - 2:r + 3, c - d - 2:c - d + 3]
            ssd = ((A - B) ** 2).sum()  # B.2
            assert m[r, c, k] == pytest.approx(1 - ssd / (25 * 3), abs=1e-10)


def test_fractional_disparity_uses_linear_interpolation():
    rng = np.random.default_rng(2)
    left, right = _pair(rng, (10, 16, 1))
    d = 2.25
    m, valid = M.match_measure(left, right, [d], window=3, eps=0.0)
    # independent route: resample the right image with np.interp, then integer NCC
    xs = np.arange(16) - d
    shifted = np.stack([np.interp(xs, np.arange(16), right[r, :, 0]) for r in range(10)])
    for r, c in ((3, 6), (5, 9), (7, 13)):
        A = left[r - 1:r + 2, c - 1:c + 2]
        B = shifted[r - 1:r + 2, c - 1:c + 2, None]
        assert m[r, c, 0] == pytest.approx((_ncc_direct(A, B, 0.0) + 1) / 2, abs=1e-10)
    np.testing.assert_array_equal(valid[0, :, 0], xs >= 0)


def test_shifted_pair_peaks_at_true_disparity():
    rng = np.random.default_rng(3)
    right = rng.random((15, 30))
    k = 4
    left = np.empty_like(right)
    left[:, k:] = right[:, :-k]           # left x  <->  right x - k
    left[:, :k] = rng.random((15, k))
    m, _ = M.match_measure(left, right, np.arange(8.0), eps=0.0)
    inner = m[1:-1, k + 1:-1]
    assert np.all(np.argmax(inner, axis=2) == k)
    np.testing.assert_allclose(inner[:, :, k], 1.0, atol=1e-9)


def test_flat_windows_are_uninformative():
    left = np.full((6, 10), 0.3)
    right = np.full((6, 10), 0.7)
    m, _ = M.match_measure(left, right, [0.0, 1.0], eps=1e-6)
    np.testing.assert_allclose(m, 0.5)


def test_uint8_scaled_like_float():
    rng = np.random.default_rng(4)
    a = rng.integers(0, 256, (8, 12, 3), dtype=np.uint8)
    b = rng.integers(0, 256, (8, 12, 3), dtype=np.uint8)
    m1, _ = M.match_measure(a, b, [0.0, 2.0], match="ssd")
    m2, _ = M.match_measure(a / 255.0, b / 255.0, [0.0, 2.0], match="ssd")
    np.testing.assert_allclose(m1, m2)


def test_data_energy_forms():
    d = np.array([0.0, 0.2, 0.5, 1.0])
    e = 1e-3
    np.testing.assert_allclose(M.data_energy(d, data="log", e_d=e), -np.log((1 - e) * d + e))
    s = 0.3
    expect = -np.log((1 - e) * np.exp(-(1 - d) / s) + e)  # 6.23 with F = 1 - d (6.5)
    np.testing.assert_allclose(M.data_energy(d, data="robust", e_d=e, sigma_d=s), expect)
    assert M.data_energy(np.array([1.0]))[0] == pytest.approx(0.0, abs=1e-12)


def test_pixel_to_node_means_touching_pixels():
    rng = np.random.default_rng(5)
    pix = rng.random((3, 4, 2))
    node = M.pixel_to_node(pix)
    assert node.shape == (4, 5, 2)
    for i in range(4):
        for j in range(5):
            touching = [pix[r, c] for r in (i - 1, i) for c in (j - 1, j)
                        if 0 <= r < 3 and 0 <= c < 4]
            np.testing.assert_allclose(node[i, j], np.mean(touching, axis=0))


def test_node_costs_unmatched_pixels_get_half_measure():
    rng = np.random.default_rng(6)
    left, right = _pair(rng, (6, 10, 1))
    disp = np.array([0.0, 7.0])
    costs = M.node_costs(left, right, disp, e_d=0.0)
    # node column 0 touches only pixel column 0, which has no match at d = 7
    np.testing.assert_allclose(costs[:, 0, 1], np.log(2.0))


@pytest.mark.parametrize(("kwargs", "word"), [
    ({"window": 4}, "window"),
    ({"window": 0}, "window"),
    ({"match": "sad"}, "match"),
    ({"eps": -1.0}, "eps"),
])
def test_bad_settings(kwargs, word):
    a = np.zeros((5, 6))
    with pytest.raises(ValueError, match=word):
        M.match_measure(a, a, [0.0], **kwargs)


def test_bad_images():
    a = np.zeros((5, 6))
    with pytest.raises(ValueError, match="same shape"):
        M.match_measure(a, np.zeros((5, 7)), [0.0])
    bad = a.copy()
    bad[1, 1] = np.nan
    with pytest.raises(ValueError, match="left contains NaN"):
        M.match_measure(bad, a, [0.0])
    with pytest.raises(ValueError, match="right must be an integer or floating"):
        M.match_measure(a, a.astype(bool), [0.0])
    with pytest.raises(ValueError, match="left must have shape"):
        M.match_measure(np.zeros((2, 3, 4, 5)), a, [0.0])
    with pytest.raises(ValueError, match="disparities"):
        M.match_measure(a, a, [np.nan])
    with pytest.raises(ValueError, match="e_d"):
        M.data_energy(np.zeros(3), e_d=1.0)
    with pytest.raises(ValueError, match="data"):
        M.data_energy(np.zeros(3), data="quadratic")

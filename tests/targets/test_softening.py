"""Softening (5.69-5.72) on a generic target."""

from __future__ import annotations

import numpy as np
import pytest

from mrfpe.targets import Softened, softened
from mrfpe.testing import CorrelatedGaussian


def test_softening_identity():
    t = CorrelatedGaussian()
    x = np.random.default_rng(0).random((200, 3))
    x[0] = [2.0, 0.5, 0.5]  # outside: stays -inf
    for power in (0.25, 1.0, 3.0):
        s = softened(t, power)
        lp, ls = t.log_prob(x), s.log_prob(x)
        assert ls[0] == -np.inf
        np.testing.assert_allclose(ls[1:], power * lp[1:], rtol=1e-15)
        # 5.69: normalised weights pi^l / sum pi^l
        w = np.exp(lp[1:] - lp[1:].max()) ** power
        ws = np.exp(ls[1:] - ls[1:].max())
        np.testing.assert_allclose(ws / ws.sum(), w / w.sum(), rtol=1e-10)
    assert softened(t, 0.5).cost == t.cost
    np.testing.assert_array_equal(softened(t, 0.5).bounds, t.bounds)


def test_composition_and_partition():
    t = CorrelatedGaussian()
    x = np.random.default_rng(1).random((10, 3))
    s = softened(softened(t, 0.5), 0.4)
    assert isinstance(s, Softened) and s.power == pytest.approx(0.2)
    np.testing.assert_allclose(s.log_prob(x), 0.2 * t.log_prob(x), rtol=1e-14)
    parts = softened(t, 0.5).partition(3, "block")
    np.testing.assert_allclose(sum(p.log_prob(x) for p in parts), 0.5 * t.log_prob(x), rtol=1e-12)
    assert sum(p.cost for p in parts) == pytest.approx(1.0)


def test_bad_power():
    t = CorrelatedGaussian()
    for bad in (0, -1, np.inf, np.nan, "x"):
        with pytest.raises(ValueError, match="power"):
            softened(t, bad)
    with pytest.raises(ValueError, match="log_prob"):
        softened(object(), 0.5)
    with pytest.raises(AttributeError):
        softened(t, 0.5).residuals  # noqa: B018 - residuals would need softening too

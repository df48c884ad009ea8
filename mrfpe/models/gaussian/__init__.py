"""Gaussian MRFs: Besag's auto-normal (conditional autoregressive, CAR) model.

The model (Besag 1974, Sec. 5; Rue & Held 2005, ch. 2) on a graph with
symmetric 0/1 adjacency matrices ``W_t``, one per *coupling type* ``t`` (one
type for the whole graph, or one per lattice direction / edge type with
``directional=True``)::

    x ~ N(mu, Q^{-1}),    Q = tau (I - sum_t beta_t W_t),
    x_i | x_-i ~ N(mu_i + sum_t beta_t sum_{j ~_t i} (x_j - mu_j), 1 / tau),
    mu_i = m + z_i . gamma   (m alone without covariates).

``theta = (mean, coupling | coupling_<type>..., precision, <covariate coefficients>...)``.
The field exists iff ``Q`` is positive definite (PD): ``tau > 0`` and
``1 - sum_t beta_t lambda_t(k) > 0`` for every joint eigenvalue ``lambda(k)`` of
the ``W_t``. Every estimator's ``log_prob`` is ``-inf`` outside that region (and
outside the bounds), never NaN.

Estimators (``GaussianMRF.target(estimator, data, ...)``), all batched over
theta ``(N, d)``: ``"pl"`` (Besag's pseudolikelihood), ``"coding"`` (one colour
class of it), ``"block"`` (block pseudolikelihood), ``"exact"`` (the exact
likelihood), ``"likelihood"`` (unnormalised, with an exact simulator, for
doubly-intractable samplers) and ``"pl_adjusted"`` (the calibrated PL of
:mod:`mrfpe.models.calibration`).

Modules
-------
:mod:`~mrfpe.models.gaussian.model` (:class:`GaussianMRF`, :func:`autonormal`),
:mod:`~mrfpe.models.gaussian.structure` (:class:`CARStructure`: the ``W_t`` on one
graph, their spectra, the PD region, log-determinants and exact simulation),
:mod:`~mrfpe.models.gaussian.pseudolikelihood` (``"pl"``, ``"coding"``, ``"block"``:
:class:`GaussianPLTarget`, :class:`GaussianBlockTarget`),
:mod:`~mrfpe.models.gaussian.likelihood` (``"exact"``, ``"likelihood"``:
:class:`GaussianExactTarget`, :class:`GaussianLikelihoodTarget`),
:mod:`~mrfpe.models.gaussian.base` (:class:`GaussianTarget`, what they share),
:mod:`~mrfpe.models.gaussian.bounds` (the default bounds),
:mod:`~mrfpe.models.gaussian.options` (each estimator's options, block partitions)
and :mod:`~mrfpe.models.gaussian.data` (checks of the arrays given). Everything
public is re-exported here.

References: J. Besag (1974), Spatial interaction and the statistical analysis of
lattice systems, JRSS B 36; H. Rue and L. Held (2005), Gaussian Markov Random
Fields, Chapman & Hall, ch. 2.
"""

from __future__ import annotations

from mrfpe.models.gaussian.base import GaussianTarget
from mrfpe.models.gaussian.likelihood import GaussianExactTarget, GaussianLikelihoodTarget
from mrfpe.models.gaussian.model import GaussianMRF, autonormal
from mrfpe.models.gaussian.options import COMMON as COMMON
from mrfpe.models.gaussian.options import ESTIMATOR_OPTIONS as ESTIMATOR_OPTIONS
from mrfpe.models.gaussian.options import MAX_BLOCK_NODES
from mrfpe.models.gaussian.options import make_blocks as make_blocks
from mrfpe.models.gaussian.pseudolikelihood import GaussianBlockTarget, GaussianPLTarget
from mrfpe.models.gaussian.structure import (
    MAX_DENSE_NODES,
    MAX_DENSE_SIMULATION,
    MAX_EIGEN_NODES,
    MAX_SPARSE_NODES,
    CARStructure,
)
from mrfpe.models.gaussian.structure import PD_EPS as PD_EPS

__all__ = ["MAX_BLOCK_NODES", "MAX_DENSE_NODES", "MAX_DENSE_SIMULATION", "MAX_EIGEN_NODES",
           "MAX_SPARSE_NODES", "CARStructure", "GaussianBlockTarget", "GaussianExactTarget",
           "GaussianLikelihoodTarget", "GaussianMRF", "GaussianPLTarget", "GaussianTarget",
           "autonormal"]
# COMMON, ESTIMATOR_OPTIONS, make_blocks and PD_EPS (imported ``as`` themselves above) stay
# importable from here, as they were from the single module this package replaced.

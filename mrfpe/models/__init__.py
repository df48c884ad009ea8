"""Declared Markov random fields: graph, states and potentials in; every estimator out.

A model states its graph (:func:`lattice` with 4- or 8-neighbourhoods or any
offsets, :func:`from_adjacency`, :func:`from_networkx`), its states (``q``
discrete states, or Gaussian for :func:`autonormal`) and its potentials
(log-linear :class:`Field`, :class:`Coupling`, :class:`NodeCovariate`,
:class:`EdgeCovariate` terms with tied parameters, or a general
:class:`Potential`); everything else is generated::

    m = models.MRF(models.lattice(4, directional=True), n_states=2,
                   terms=[models.Coupling("product", by_type=True), models.Field("value"),
                          models.NodeCovariate("z", kind="value")], state_values=(-1, 1))
    x = m.simulate(theta, shape=(64, 64), covariates={"z": z}, seed=0)
    m.target("pl", x, covariates={"z": z})           # Besag's pseudolikelihood
    m.target("coding", x, coding=1, covariates=...)  # a coding estimator
    m.target("block", x, block=(2, 2), ...)          # block pseudolikelihood
    m.target("exact", x[:, :8], ...)                 # exact likelihood, where tractable

Every target is a batched :class:`mrfpe.targets.Target`, so every sampler and
``mrfpe.targets.maximise`` works on it. Ready-made models: :func:`potts`,
:func:`ising`, :func:`autologistic`, :func:`autonormal` and the thesis's
``"brdf"``; all are registered under the ``mrfpe.models`` entry-point group
(:func:`get`, :func:`names`), as third-party models are.

Hidden fields: ``models.hidden(mrf, emission)`` declares a discrete MRF over hidden
labels seen through an emission of :mod:`mrfpe.models.emissions` (``models.emissions.
gaussian()``, ``poisson()``, ``categorical()``, ``general(...)``); the ``hidden``
sampler draws its posterior (:mod:`mrfpe.models.hidden`).
"""

from __future__ import annotations

from mrfpe.models import emissions
from mrfpe.models.base import Model
from mrfpe.models.discrete import MRF, Potential
from mrfpe.models.gaussian import autonormal
from mrfpe.models.graph import Graph, LatticeSpec, from_adjacency, from_networkx, lattice
from mrfpe.models.hidden.model import hidden  # bound after the package: models.hidden is it
from mrfpe.models.library import autologistic, ising, potts
from mrfpe.models.registry import get, names, registry
from mrfpe.models.terms import Coupling, EdgeCovariate, Field, NodeCovariate, Term

__all__ = ["MRF", "Coupling", "EdgeCovariate", "Field", "Graph", "LatticeSpec", "Model",
           "NodeCovariate", "Potential", "Term", "autologistic", "autonormal", "emissions",
           "from_adjacency", "from_networkx", "get", "hidden", "ising", "lattice", "names",
           "potts", "registry"]


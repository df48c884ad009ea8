"""Emissions: how an observation depends on its hidden label, ``p(y_i | x_i = a, φ)``.

The second half of a hidden Markov random field (:func:`mrfpe.models.hidden`)::

    from mrfpe import models
    hm = models.hidden(models.potts(3), models.emissions.gaussian(shared_sd=True))
    hm.param_names()   # ('coupling', 'field_1', 'field_2', 'mean_0', 'mean_1', 'mean_2', 'sd')

=========================================  =============================================
emission                                   parameters, prior, update
=========================================  =============================================
``gaussian(shared_sd=True)``               ``mean_a``, ``sd`` (or ``sd_a``); normal and
                                           inverse-gamma; conjugate Gibbs, means ordered
``poisson(exposure=None)``                 ``rate_a``; gamma; conjugate, rates ordered
``categorical(n_categories=None)``         ``prob_a_c``; Dirichlet rows; conjugate
``general(log_density, params)``           yours; flat on their bounds; random walk
=========================================  =============================================

Each is an :class:`Emission` declaration; :meth:`Emission.bind` ties it to ``q``
states and a data set (a :class:`BoundEmission`: batched log-likelihoods, priors,
conditionally conjugate updates, EM's M-step, a start). Emissions are entry-point
plugins of the group ``mrfpe.emissions`` (:func:`get`, :func:`names`); a plugin is
checked with :func:`mrfpe.testing.check_emission`.
"""

from __future__ import annotations

from mrfpe.models.emissions.base import BoundEmission, Emission
from mrfpe.models.emissions.categorical import Categorical, categorical
from mrfpe.models.emissions.gaussian import Gaussian, gaussian
from mrfpe.models.emissions.general import General, general
from mrfpe.models.emissions.poisson import Poisson, poisson
from mrfpe.models.emissions.registry import get, names, registry

__all__ = ["BoundEmission", "Categorical", "Emission", "Gaussian", "General", "Poisson",
           "categorical", "gaussian", "general", "get", "names", "poisson", "registry"]

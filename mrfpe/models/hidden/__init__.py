"""Hidden Markov random fields: a declared discrete MRF over labels, seen through noise.

::

    import mrfpe
    from mrfpe import models
    from mrfpe.models.hidden import icm, mean_field_em

    hm = models.hidden(models.potts(2), models.emissions.gaussian())
    hm.param_names()                         # ('coupling', 'field', 'mean_0', 'mean_1', 'sd')
    x, y = hm.simulate([0.8, 0.0, 0.0, 1.0, 0.5], shape=(32, 32), seed=0)
    target = hm.target("hidden", y, fixed={"field": 0.0})
    post = mrfpe.sample("hidden", target, seed=0)
    post["label_probability"]                # (row, col, state) posterior marginals
    icm(target)                              # Besag's ICM, kind="optima"
    mean_field_em(target)                    # Celeux et al.'s mean-field EM

(``models.hidden`` is the declaring function; the package's other names are imported
from ``mrfpe.models.hidden``.)

:func:`hidden` declares the model (:class:`HiddenModel`); its ``target("hidden", y,
method=, fixed=, bounds=, mask=, covariates=, surrogate=)`` is a :class:`HiddenTarget`;
:func:`build_surrogate` pre-computes the :class:`Surrogate` of ``method="surrogate"``
(on a ``dask.distributed`` client if given);
:func:`icm` and :func:`mean_field_em` are point estimates; the ``hidden`` sampler
(:mod:`mrfpe.samplers.hidden`) draws the posterior.
"""

from __future__ import annotations

from mrfpe.models.hidden.model import HiddenModel, hidden
from mrfpe.models.hidden.point import icm, mean_field_em
from mrfpe.models.hidden.surrogate import Surrogate
from mrfpe.models.hidden.surrogate_build import build_surrogate
from mrfpe.models.hidden.target import METHODS, HiddenTarget

__all__ = ["METHODS", "HiddenModel", "HiddenTarget", "Surrogate", "build_surrogate", "hidden",
           "icm", "mean_field_em"]

"""Multiple-seed local optimisers: Levenberg–Marquardt (thesis 7.3.1–7.3.2) and NLopt.

Both start one local optimisation from each of ``n_seeds`` evenly spaced points
of the parameter box (512 by default, 7.3.2 step 1: "seeds ... distributed as
the samples in Fig. 7.15", i.e. the same grid as PMC's initial set,
:func:`mrfpe.samplers.kit.grid`; 8³ cell centres in 3-D). The optima are the
sample set, each weighted by its target value (``log_weight = log_target``), so
the posterior's MAP is the best optimum and the set can be compared with the
samplers' sets. The best-so-far trace runs over the seed index (step = seed),
which is what Figs. 7.3–7.6 plot against the number of seeds.

``seed_grid="even"`` (default) is the thesis's deterministic grid, so the
``seed`` argument changes nothing there except NLopt's stochastic algorithms;
``"shifted"`` moves the whole grid by one uniform random offset of at most half
a cell per axis (a randomised lattice — still evenly spaced) drawn from
``seed``, for studies of the spread due to seed placement.

These are optimisers, not samplers: the optima do not represent the
posterior's spread: the posterior is built with ``kind="optima"``, which the
conformance moment check, ``diagnose`` and the distances recognise.

The seed points and the shared driver are in :mod:`mrfpe.samplers.multistart`, the
optimisers in :mod:`mrfpe.samplers.lm_multiseed` and
:mod:`mrfpe.samplers.nlopt_multiseed`; this module re-exports them under the path the
``lm_multiseed`` and ``nlopt_multiseed`` entry points name.
"""

from __future__ import annotations

from mrfpe.samplers.lm_multiseed import NONFINITE_RESIDUAL, LMMultiSeed
from mrfpe.samplers.multistart import MultiSeedOptimiser, seed_points
from mrfpe.samplers.nlopt_multiseed import NLoptMultiSeed

__all__ = ["NONFINITE_RESIDUAL", "LMMultiSeed", "MultiSeedOptimiser", "NLoptMultiSeed",
           "seed_points"]

"""Chain-length checks and start points for the chain samplers (mh, dw_q, dw_r, emcee).

Book-keeping (evaluation counts, MAP trace, progress, callback) is
:class:`mrfpe.samplers._common.Run`; this module adds what only chains need.
Private to mrfpe: third-party plugins use the public API only.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mrfpe.samplers.base import check_positive_int

__all__ = ["check_chain_length", "draw_in_support"]


def check_chain_length(n_steps: Any, burn_in: Any, thin: Any) -> tuple[int, int, int]:
    """Validate ``n_steps`` >= 1, 0 <= ``burn_in`` < ``n_steps`` and ``thin`` >= 1."""
    n_steps = check_positive_int("n_steps", n_steps)
    burn_in_ = check_positive_int("burn_in", burn_in, minimum=0)
    if burn_in_ >= n_steps:
        raise ValueError(f"burn_in must be < n_steps ({n_steps}); got {burn_in}")
    return n_steps, burn_in_, check_positive_int("thin", thin)


def draw_in_support(run: Any, target: Any, rng: np.random.Generator, n: int,
                    bounds: np.ndarray, max_draws: int = 2048,
                    ) -> tuple[np.ndarray, np.ndarray]:
    """``n`` uniform draws in the box, with -inf ones replaced by further uniform draws.

    Candidates are drawn and evaluated through ``run.evaluate`` (so they are
    counted) in batches of ``max(n, 32)`` until every row is finite or about
    ``max_draws`` extra candidates have been tried. Rows still -inf are then
    replaced by copies of finite draws when there are any (chains separate
    through their moves); if none is finite the uniform draws are returned as
    they are, so a sampler survives a target that is -inf almost everywhere.

    Returns
    -------
    theta : (n, d) start points; log_target : (n,) their log densities.
    """
    lo, hi = bounds[:, 0], bounds[:, 1]
    theta = lo + (hi - lo) * rng.random((n, lo.size))
    lp = run.evaluate(target, theta)
    batch = max(n, 32)
    for _ in range(-(-max_draws // batch)):
        bad = np.flatnonzero(~np.isfinite(lp))
        if bad.size == 0:
            break
        cand = lo + (hi - lo) * rng.random((batch, lo.size))
        lpc = run.evaluate(target, cand)
        good = np.flatnonzero(np.isfinite(lpc))[: bad.size]
        theta[bad[: good.size]], lp[bad[: good.size]] = cand[good], lpc[good]
    bad = ~np.isfinite(lp)
    if bad.any() and not bad.all():
        src = rng.choice(np.flatnonzero(~bad), size=int(bad.sum()))
        theta[bad], lp[bad] = theta[src], lp[src]
    return theta, lp

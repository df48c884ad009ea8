"""A plain-text report of a posterior: :func:`summary`."""

from __future__ import annotations

import math

import numpy as np
import xarray as xr

from mrfpe.posterior.caveats import caveats
from mrfpe.posterior.diagnostics import diagnose, stored_messages
from mrfpe.posterior.statistics import map_estimate, weighted_cov, weighted_mean, weighted_quantiles
from mrfpe.resampling import ess, perplexity

__all__ = ["summary"]


def _diagnostics_lines(post: xr.Dataset) -> list[str]:
    if "diag_reliable" in post.attrs:
        a = post.attrs
        d = {"ess": a["diag_ess"], "pareto_k": a["diag_pareto_k"], "rhat": a["diag_rhat"],
             "reliable": bool(a["diag_reliable"]), "messages": stored_messages(post)}
    else:  # a posterior from before diagnostics were stored
        d = diagnose(post)

    def fmt(x: float, spec: str) -> str:
        return "n/a" if x is None or math.isnan(x) else format(x, spec)

    kind = post.attrs.get("kind", "draws")
    lines = [f"kind {kind}; diagnostics: ESS {fmt(d['ess'], '.1f')}, Pareto k̂ "
             f"{fmt(d['pareto_k'], '.2f')}, R̂ {fmt(d['rhat'], '.3f')}: "
             + ("reliable" if d["reliable"] else "UNRELIABLE")]
    lines += [f"  - {m}" for m in d["messages"]]
    stored = post.attrs.get("diag_caveats")
    lines += [f"  caveat: {c}" for c in (caveats(post) if stored is None
                                         else str(stored).splitlines())]
    ev = post.attrs.get("log_evidence")
    if ev is not None:
        lines.append(f"log evidence (relative to the box: log ∫p / vol) {ev:.6g} ± "
                     f"{post.attrs.get('log_evidence_se', float('nan')):.3g}")
    return lines


def summary(post: xr.Dataset) -> str:
    """A plain-text report: sampler, ESS, perplexity, evaluations, time, the diagnostics
    (:func:`mrfpe.posterior.diagnose`: ESS, Pareto k̂, R̂, the verdict and why), the log
    evidence if stored, and per parameter the weighted mean ± sd, the 5/50/95 %
    quantiles and the MAP."""
    mean, cov = weighted_mean(post), weighted_cov(post)
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    q = weighted_quantiles(post, [0.05, 0.5, 0.95])
    m, m_lt = map_estimate(post)
    names = [str(p) for p in post["param"].values]
    w = max(9, *(len(n) for n in names))
    lines = [
        f"sampler {post.attrs.get('sampler', '?')}: {post.sizes['sample']} samples, "
        f"Kish ESS {ess(post):.1f}, perplexity {perplexity(post):.3f}, "
        f"{post.attrs.get('n_target_evals', float('nan')):.4g} target evaluations, "
        f"{post.attrs.get('wall_time_s', float('nan')):.3g} s; MAP log target {m_lt:.6g}",
        *_diagnostics_lines(post),
        f"{'param':<{w}} {'mean':>10} {'sd':>10} {'5%':>10} {'50%':>10} {'95%':>10} {'MAP':>10}",
    ]
    for j, n in enumerate(names):
        lines.append(f"{n:<{w}} {mean[j]:>10.4g} {sd[j]:>10.4g} {q[0, j]:>10.4g} "
                     f"{q[1, j]:>10.4g} {q[2, j]:>10.4g} {m[j]:>10.4g}")
    return "\n".join(lines)

"""The demo's figure: where the posterior lies, and how PMC got there.

Three panels, each zoomed to where the posterior's weight is (with the truth
kept in view): the specular reflectance against the roughness (the pair the
image determines least well) over the pseudolikelihood's slice through the MAP,
the diffuse reflectance as a weighted histogram, and the MAP's distance to the
truth over the iterations.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["CAPTION", "LABELS", "posterior_figure"]

#: Axis labels in words for the Ward parameters (unit cube); others keep their names.
LABELS = {"rho_d": "diffuse reflectance ρ_d", "rho_s": "specular reflectance ρ_s",
          "alpha": "roughness α"}

#: What the figure shows, for the report (``report.md``) and the docs.
CAPTION = (
    "Left: the posterior of the specular reflectance ρ_s and the roughness α, as the PMC "
    "particles (white, area ∝ weight) over the log pseudolikelihood on the slice through "
    "the MAP (brighter is higher; the top 20 log units). Middle: the posterior of the "
    "diffuse reflectance ρ_d (weighted histogram). Right: the distance of the best point "
    "found so far (the MAP) to the truth after each PMC iteration; it can rise when the "
    "pseudolikelihood prefers a point farther from the truth, as along a flat ridge. "
    "Red +: the true parameters; black ×: the MAP. All values in the unit cube the sampler "
    "works in.")


def _window(values: np.ndarray, w: np.ndarray, keep: list[float],
            bounds: tuple[float, float]) -> tuple[float, float]:
    """The range holding 99.5 % of the weight and the points ``keep``, padded by 10 %."""
    order = np.argsort(values)
    cdf = np.cumsum(w[order])
    lo = values[order][np.searchsorted(cdf, 0.0025 * cdf[-1])]
    hi = values[order][min(np.searchsorted(cdf, 0.9975 * cdf[-1]), values.size - 1)]
    lo, hi = min(lo, *keep), max(hi, *keep)
    pad = max(0.1 * (hi - lo), 1e-4)
    return max(bounds[0], lo - pad), min(bounds[1], hi + pad)


def posterior_figure(target: Any, post: Any, truth: np.ndarray, path: Path,
                     n_grid: int = 60) -> None:
    """Write the demo's three-panel PNG (see the module docstring) to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mrfpe.posterior import map_estimate, weights

    m, _ = map_estimate(post)
    names = [str(p) for p in post["param"].values]
    label = [LABELS.get(n, n) for n in names]
    x, w = post["theta"].values, weights(post)
    b = np.asarray(target.bounds, dtype=float)
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.4), constrained_layout=True,
                             gridspec_kw={"width_ratios": [1.15, 1, 1]})

    # Left: ρ_s against α (parameters 1 and 2) over the PL slice through the MAP.
    i, j = 1, 2
    xi = _window(x[:, i], w, [truth[i], m[i]], tuple(b[i]))
    xj = _window(x[:, j], w, [truth[j], m[j]], tuple(b[j]))
    gi, gj = np.linspace(*xi, n_grid), np.linspace(*xj, n_grid)
    pts = np.tile(m, (n_grid * n_grid, 1))
    pts[:, i] = np.repeat(gi, n_grid)
    pts[:, j] = np.tile(gj, n_grid)
    lp = target.log_prob(pts).reshape(n_grid, n_grid)
    finite = np.isfinite(lp)
    top = lp[finite].max() if finite.any() else 0.0
    img = np.where(finite, np.maximum(lp - top, -20.0), -20.0)
    ax = axes[0]
    im = ax.imshow(img.T, origin="lower", extent=(*xi, *xj), aspect="auto", cmap="viridis",
                   interpolation="bilinear")
    ax.scatter(x[:, i], x[:, j], s=2 + 40 * w / max(w.max(), 1e-300), c="white", alpha=0.6,
               linewidths=0)
    ax.plot(truth[i], truth[j], "r+", ms=16, mew=2.5, label="truth")
    ax.plot(m[i], m[j], "kx", ms=11, mew=2.5, label="MAP")
    ax.set(xlabel=label[i], ylabel=label[j], xlim=xi, ylim=xj,
           title="Specular reflectance against roughness")
    ax.legend(loc="upper right", framealpha=0.9)
    fig.colorbar(im, ax=ax, shrink=0.85, label="log pseudolikelihood − its maximum")

    # Middle: ρ_d, the parameter the image pins down best.
    k = 0
    ax = axes[1]
    xk = _window(x[:, k], w, [truth[k], m[k]], tuple(b[k]))
    ax.hist(x[:, k], bins=np.linspace(*xk, 41), weights=w, color="0.55")
    ax.axvline(truth[k], color="r", lw=2, label="truth")
    ax.axvline(m[k], color="k", lw=1.5, ls="--", label="MAP")
    ax.set(xlabel=label[k], ylabel="posterior weight", title="Diffuse reflectance")
    ax.ticklabel_format(axis="x", useOffset=False)
    ax.xaxis.set_major_locator(plt.MaxNLocator(4))  # long labels: few ticks
    ax.legend(loc="upper right", framealpha=0.9)

    # Right: the MAP's distance to the truth per iteration.
    ax = axes[2]
    trace = np.linalg.norm(post["map_theta"].values - truth, axis=1)
    ax.plot(np.arange(1, trace.size + 1), trace, "o-", color="C0")
    ax.set(xlabel="PMC iteration", ylabel="|MAP − truth| (unit cube)", ylim=(0, None),
           title="Best-scoring point's distance to the truth")
    ax.grid(alpha=0.3)
    fig.savefig(path, dpi=100)
    plt.close(fig)

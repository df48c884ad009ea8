"""Self-normalised importance sampling error against its closed-form asymptote (runner example).

Every weighted sampler in mrfpe (SIR, PPF, PMC) estimates posterior moments
by self-normalised importance sampling (SNIS): draws x_i ~ q, weights
w_i ∝ p(x_i)/q(x_i), estimate Σ w_i x_i. This study measures the root mean
squared error of the SNIS mean of a Gaussian target p = N(μ, s²I) under a
Gaussian proposal q = N(0, t²I) for growing sample sizes n, and sets it
beside the delta-method asymptote RMSE ≈ sqrt(Σ_j V_j / n) with

    V_j = E_q[(p/q)² (x_j − μ_j)²] = (Π_k Z_k) (1/a + (m_j − μ_j)²),
    a = 2/s² − 1/t²,  m_j = (2μ_j/s²)/a,
    Z_k = ∫ p_k²/q_k dx = (t/s²) a^(−1/2) exp((2μ_k/s²)²/(2a) − μ_k²/s²),

finite when t² > s²/2. The ratio should tend to 1 as n grows. It needs no
BRDF or sampler, so it also serves as the smallest example of a study (see
docs/studies.md) and as the runner's test subject.

Full run: about 25 s on two cores (4 sample sizes × 200 trials; mostly netCDF I/O).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import xarray as xr

from mrfpe.experiments.writeup import markdown_table, new_figure, save_figure, write_report
from mrfpe.study import Setting, Study, by_cell


def _positive(value: float | list) -> None:
    for v in value if isinstance(value, list) else [value]:
        if not v > 0:
            raise ValueError(f"must be > 0; got {v!r}")


def asymptotic_rmse(mu: np.ndarray, s: float, t: float, n: int) -> float:
    """Delta-method RMSE of the SNIS mean (module docstring); inf when t² ≤ s²/2."""
    mu = np.asarray(mu, dtype=float)
    a = 2.0 / s**2 - 1.0 / t**2
    if a <= 0:
        return float("inf")
    b = 2.0 * mu / s**2
    log_z = np.log(t / s**2) - 0.5 * np.log(a) + b**2 / (2 * a) - mu**2 / s**2
    v = np.exp(log_z.sum()) * (1.0 / a + (b / a - mu) ** 2)
    return float(np.sqrt(v.sum() / n))


def trial(config: dict, repeat: int, seed: int) -> xr.Dataset:
    """One SNIS estimate of the target mean from ``n_samples`` proposal draws."""
    rng = np.random.default_rng(seed)
    mu = np.asarray(config["mu"], dtype=float)
    s, t, n = config["sigma"], config["proposal_sigma"], config["n_samples"]
    x = rng.normal(0.0, t, size=(n, mu.size))
    log_w = -0.5 * (((x - mu) / s) ** 2).sum(1) + 0.5 * ((x / t) ** 2).sum(1)
    w = np.exp(log_w - log_w.max())
    w /= w.sum()
    estimate = w @ x
    return xr.Dataset(
        {"error": (("param",), estimate - mu), "ess": ((), 1.0 / np.sum(w**2))},
        coords={"param": [f"x{j}" for j in range(mu.size)]},
    )


def summarise(results: list[xr.Dataset], config: dict, out_dir: Path) -> str:
    """RMSE per sample size beside the asymptote; log-log figure."""
    mu = np.asarray(config["mu"], dtype=float)
    rows, ns, emp, theo = [], [], [], []
    for (n,), group in by_cell(results, "n_samples").items():
        err = np.stack([ds["error"].values for ds in group])
        rmse = float(np.sqrt((err**2).sum(1).mean()))
        sq = (err**2).sum(1)  # s.e. of sqrt(mean) by the delta method
        se = float(sq.std(ddof=1) / np.sqrt(sq.size) / (2 * rmse)) if sq.size > 1 else np.nan
        ref = asymptotic_rmse(mu, config["sigma"], config["proposal_sigma"], n)
        ess = float(np.mean([ds["ess"].item() for ds in group]))
        rows.append([n, len(group), rmse, se, ref, rmse / ref, ess])
        ns.append(n), emp.append(rmse), theo.append(ref)
    table = markdown_table(["n", "trials", "RMSE", "± s.e.", "asymptote", "ratio", "mean ESS"],
                           rows)
    fig, ax = new_figure(size=(5, 4))
    ax = ax[0, 0]
    ax.loglog(ns, emp, "o-", label="SNIS (this study)")
    ax.loglog(ns, theo, "k--", label="delta-method asymptote")
    ax.set(xlabel="samples n", ylabel="RMSE of the mean", title="Self-normalised IS")
    ax.legend()
    png = save_figure(fig, out_dir / "rmse.png")
    write_report(out_dir, "Self-normalised importance sampling: RMSE against the asymptote", [
        f"Target N(μ={mu.tolist()}, {config['sigma']}²I), proposal "
        f"N(0, {config['proposal_sigma']}²I); config: `{json.dumps(config)}`.",
        table,
        "The ratio RMSE / asymptote should approach 1 as n grows (it exceeds 1 at small n, "
        "where the O(1/n) bias of the self-normalised estimate still matters).",
        f"![RMSE]({png})",
    ])
    return table


STUDY = Study(
    name="importance_sampling",
    doc=__doc__,
    config={"n_trials": 200, "seed": 1},
    settings=[
        Setting("n_samples", [10, 100, 1000, 10000], "importance samples n, one grid column "
                "each", check=_positive),
        Setting("mu", [0.3, -0.2], "mean μ of the Gaussian target (its length is the "
                "dimension)"),
        Setting("sigma", 0.5, "standard deviation s of the target", check=_positive),
        Setting("proposal_sigma", 1.0, "standard deviation t of the proposal N(0, t²I); the "
                "asymptote needs t² > s²/2", check=_positive),
    ],
    quick={"n_trials": 20, "n_samples": [10, 100, 1000]},
    trial=trial,
    summarise=summarise,
    grid=("n_samples",),
)

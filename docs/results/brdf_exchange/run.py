"""The exact posterior of the BRDF MRF on a narrow strip, against exchange, exp(PL), pl_adjusted.

On an H x W image the node lattice has W + 1 columns of H + 1 nodes. With the pixel
data term and no unary prior, U(x; theta) is a sum of pixel terms, each coupling two
neighbouring columns, so log Z(theta) = log sum_x exp(-U) is a product of transfer
matrices over the columns' B^(H+1) joint labels (checked against enumeration with
``check``). The exact posterior over theta (flat on the unit cube) is then computed
on a G^3 grid, and compared with what the library's samplers return.

Usage (from the repository root)::

    python docs/results/brdf_exchange/run.py SIGMA H W B G check          # log Z vs enumeration
    python docs/results/brdf_exchange/run.py 0.005 2 16 3 31 run pl,ex 0 3000
    python docs/results/brdf_exchange/run.py 0.005 2 16 3 31 run adj 300

Arguments: sigma_b, image height and width, labels, grid points per axis, then
``check`` or ``run`` with the methods (``pl``: PMC on exp(PL); ``adj``: PMC on
pl_adjusted with N_DRAWS; ``ex``: the exchange sampler with N_STEPS).
"""
import itertools
import sys
import time
import warnings

import numpy as np
from scipy.special import logsumexp

import mrfpe
from mrfpe.models import get
from mrfpe.brdf.simulate import label_field
from mrfpe.brdf.label_render import term_energies
from mrfpe.brdf.synthetic import make_scene
from mrfpe.brdf.targets import reflectance

sigma, H, W, B, G = (float(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]),
                     int(sys.argv[5]))
seed = 3
sc = make_scene("ward", theta=[0.5, 0.3, 0.2], shape=(H, W), n_labels=B, seed=seed, noise=0.01)
f = label_field(sc, sigma_b=sigma, data_term="pixel", prior="none")
nc, K = W + 1, H + 1
combos = np.array(list(itertools.product(range(B), repeat=2 * K)))  # (left column, right column)
lab = np.empty((len(combos), K, nc), dtype=np.int64)
lab[:, :, 0::2] = combos[:, :K, None]
lab[:, :, 1::2] = combos[:, K:, None]
lab = lab.reshape(len(combos), -1)
powers = B ** np.arange(2 * K - 1, -1, -1)
code = combos @ powers
swapped = np.concatenate([combos[:, K:], combos[:, :K]], axis=1) @ powers
swap = np.argsort(code)[swapped]  # labelling holding the swapped combo

def log_z(theta):
    coef = reflectance.coefficients(sc.model, sc.model.to_natural(theta))
    D = term_energies(f, coef, lab).reshape(theta.shape[0], len(combos), H, W).sum(axis=2)
    N, S = theta.shape[0], B ** K
    la = np.zeros((N, S))
    for c in range(W):
        Dc = (D[:, :, c] if c % 2 == 0 else D[:, swap, c]).reshape(N, S, S)
        la = logsumexp(la[:, :, None] - Dc, axis=1)
    return logsumexp(la, axis=1)

if len(sys.argv) > 6 and sys.argv[6] == "check":  # brute force on a tiny lattice
    from mrfpe.brdf.simulate import label_energy
    X = np.array(list(itertools.product(range(B), repeat=K * nc)))
    th = np.array([[0.3, 0.6, 0.4], [0.7, 0.2, 0.5]])
    print([float(logsumexp(-label_energy(f, t, X))) for t in th], log_z(th))
    sys.exit()

m = get("brdf")
lik = m.target("likelihood", sc, sigma_b=sigma, data_term="pixel")
g = (np.arange(G) + 0.5) / G
grid = np.array(list(itertools.product(g, g, g)))
t0 = time.time()
lz = np.concatenate([log_z(grid[i:i + 200]) for i in range(0, len(grid), 200)])
lp = lik.unnormalised(grid) - lz
pl = m.target("pl", sc, sigma_b=sigma, data_term="pixel")
lpl = pl.log_prob(grid)
print("grid", round(time.time() - t0, 1), "s", flush=True)
res = {}
for name, lg in (("exact", lp), ("exp(PL) grid", lpl)):
    w = np.exp(lg - lg.max())
    w /= w.sum()
    mean = w @ grid
    res[name] = (mean, np.sqrt(w @ (grid - mean) ** 2))
    print(name, "mean", mean.round(3), "sd", res[name][1].round(3), flush=True)
mean, sd = res["exact"]


def report(name: str, post, seconds: float, extra: str = "") -> None:
    th, lw = post["theta"].values, post["log_weight"].values
    ww = np.exp(lw - lw.max())
    ww /= ww.sum()
    em = ww @ th
    es = np.sqrt(ww @ (th - em) ** 2)
    print(f"{name}: {seconds:.1f} s; mean {em.round(3)} sd {es.round(3)} "
          f"z {((em - mean) / sd).round(2)} ratio {(es / sd).round(2)} "
          f"reliable {post.attrs.get('diag_reliable')} {extra}", flush=True)
    if not post.attrs.get("diag_reliable"):
        print("   ", str(post.attrs.get("diag_messages", "")).replace("\n", "; "), flush=True)


which = sys.argv[7].split(",")
n_draws = int(sys.argv[8]) if len(sys.argv) > 8 else 1000
n_steps = int(sys.argv[9]) if len(sys.argv) > 9 else 3000
with warnings.catch_warnings():
    warnings.simplefilter("ignore")  # each result's reliability is printed instead
    if "pl" in which:
        t0 = time.time()
        report("exp(PL)+PMC", mrfpe.sample("pmc", pl, seed=0), time.time() - t0)
    if "adj" in which:
        t0 = time.time()
        try:
            adj = m.target("pl_adjusted", sc, sigma_b=sigma, data_term="pixel",
                           n_draws=n_draws)
            report("pl_adjusted+PMC", mrfpe.sample("pmc", adj, seed=0), time.time() - t0,
                   f"sweeps {adj.n_simulation_sweeps} mle {adj.mle.theta.round(3)}")
        except ValueError as e:
            print("pl_adjusted refused:", e)
    if "ex" in which:
        t0 = time.time()
        post = mrfpe.sample("exchange", lik, seed=0, n_steps=n_steps, burn_in=n_steps // 4)
        report("exchange", post, time.time() - t0, f"aux {post.attrs.get('aux_sweeps')}")

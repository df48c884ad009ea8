"""Hidden Markov random fields: every method against exact answers, coverage, and real data.

Parts (each trial one JSON file in ``trials/``; a file that exists is skipped, so an
interrupted run resumes; every random choice flows from a seed derived from the trial's
name):

* ``exact``    -- a 3-state hidden Potts field on 6 x 40, emission known (means 0, 1, 2, sd
  0.6), fields fixed at 0, β's flat prior on (-0.5, 2): the exact posterior of β (the
  transfer matrix in product form, a 501-point grid) against ``pl``, ``pl_adjusted``,
  ``exchange`` and ``surrogate`` (one surrogate for every data set), at β = 0.6, 0.8, 1.0,
  ``--n-datasets`` data sets each;
* ``coverage`` -- the same field at β = 0.8 with the emission unknown (means and sd free,
  the default priors): do the 90 % intervals of ``surrogate`` and ``exchange`` cover the
  true parameters, over ``--n-coverage`` simulated data sets;
* ``menteith`` -- the Lake of Menteith image (Marin & Robert 2014, ch. 8; 100 x 100), a
  6-state hidden Potts field with Gaussian emissions, one sd per state, every parameter
  unknown: β and the emission by the four methods, with times; the segmentation and its
  uncertainty are saved for the report's figure;
* ``laiche``   -- the Laiche presence grid (25 x 25, observed): the Ising (Potts, β only)
  posterior of β by exchange, the calibrated pseudolikelihood (PMC) and exp(PL) (PMC).

The data sets are read from ``../shared/data`` (the ``MRFPE_DATA`` environment variable
names another folder); they are not copied here.

    python docs/results/hidden_fields/run.py --part exact --n-datasets 5
    python docs/results/hidden_fields/run.py --part coverage --n-coverage 20
    python docs/results/hidden_fields/run.py --part menteith
    python docs/results/hidden_fields/run.py --part laiche
    python docs/results/hidden_fields/report.py
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings
import zlib
from pathlib import Path

import numpy as np

import mrfpe
from mrfpe import models
from mrfpe.models.hidden import build_surrogate

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[2]
TRIALS = HERE / "trials"
DATA = Path(os.environ.get("MRFPE_DATA", ROOT.parent / "shared" / "data"))
STUDY = "hidden_fields/v1"
METHODS = ("pl", "pl_adjusted", "exchange", "surrogate")

SHAPE, Q, MEANS, SD, BOUNDS = (6, 40), 3, (0.0, 1.0, 2.0), 0.6, (-0.5, 2.0)
FIELDS = {"field_1": 0.0, "field_2": 0.0}
KNOWN = {**FIELDS, "mean_0": 0.0, "mean_1": 1.0, "mean_2": 2.0, "sd": SD}
BETAS = (0.6, 0.8, 1.0)


def seed_of(name: str) -> int:
    return zlib.crc32(f"{STUDY}/{name}".encode())


def _commit() -> str:
    import subprocess

    try:
        return subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                              capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""


def write(name: str, record: dict) -> None:
    record = {**record, "mrfpe": mrfpe.__version__, "commit": _commit()}
    TRIALS.mkdir(parents=True, exist_ok=True)
    tmp = TRIALS / f".{name}.json.tmp"
    tmp.write_text(json.dumps(record, indent=1, default=float))
    tmp.replace(TRIALS / f"{name}.json")  # whole files only: an interruption leaves none


def done(name: str) -> bool:
    return (TRIALS / f"{name}.json").exists()


def sample(target, seed: int, **config) -> tuple:
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", mrfpe.PosteriorWarning)
        post = mrfpe.sample("hidden", target, seed=seed, **config)
    return post, time.perf_counter() - start


def summary(post, seconds: float, truth: dict | None = None) -> dict:
    """Per free parameter: mean, sd, 5-95 % interval (and whether it covers the truth)."""
    names = [str(n) for n in post["param"].values]
    th = post["theta"].values
    out = {"seconds": seconds, "reliable": int(post.attrs["diag_reliable"]),
           "messages": str(post.attrs.get("diag_messages", "")), "params": {}}
    for j, name in enumerate(names):
        lo, hi = np.quantile(th[:, j], [0.05, 0.95])
        row = {"mean": float(th[:, j].mean()), "sd": float(th[:, j].std()),
               "q05": float(lo), "q95": float(hi), "rhat": float(post["param_rhat"].values[j]),
               "ess": float(post["param_ess"].values[j])}
        if truth is not None and name in truth:
            row["covers"] = bool(lo <= truth[name] <= hi)
        out["params"][name] = row
    out["attrs"] = {k: post.attrs[k] for k in post.attrs
                    if k.startswith(("aux_", "surrogate_", "pl_adjusted_"))}
    return out


# -- exact ------------------------------------------------------------------------------------
def exact_posterior(y: np.ndarray) -> dict:
    sys.path.insert(0, str(ROOT))
    from tests.models.hidden.transfer import coupling_posterior

    m, sd = coupling_posterior(y, *SHAPE, Q, MEANS, SD, np.linspace(*BOUNDS, 501))
    return {"mean": m, "sd": sd}


def hidden_model(shared_sd: bool = True, **emission):
    return models.hidden(models.potts(Q), models.emissions.gaussian(shared_sd=shared_sd,
                                                                    **emission))


def run_exact(n_datasets: int) -> None:
    hm = hidden_model()
    surrogate = None
    for beta in BETAS:
        for k in range(n_datasets):
            name = f"exact_b{beta:.1f}_d{k}"
            if done(name):
                continue
            y = hm.simulate([beta, 0.0, 0.0, *MEANS, SD], shape=SHAPE, seed=seed_of(name))[1]
            record = {"part": "exact", "beta": beta, "dataset": k, "exact": exact_posterior(y)}
            for method in METHODS:
                opts = {"fixed": KNOWN, "method": method, "bounds": {"coupling": BOUNDS}}
                if method == "surrogate":
                    if surrogate is None:
                        t0 = time.perf_counter()
                        surrogate = build_surrogate(hm.target("hidden", y, **opts),
                                                    seed=seed_of("exact_surrogate"))
                        record["surrogate_build_seconds"] = time.perf_counter() - t0
                    opts["surrogate"] = surrogate
                post, sec = sample(hm.target("hidden", y, **opts), seed_of(f"{name}/{method}"))
                record[method] = summary(post, sec)
            write(name, record)
            print(name, {m: round(record[m]["params"]["coupling"]["mean"], 3) for m in METHODS},
                  record["exact"], flush=True)


# -- coverage ---------------------------------------------------------------------------------
def run_coverage(n: int) -> None:
    hm, beta = hidden_model(), 0.8
    truth = {"coupling": beta, **dict(zip(("mean_0", "mean_1", "mean_2"), MEANS)), "sd": SD}
    surrogate = None
    for k in range(n):
        name = f"coverage_d{k}"
        if done(name):
            continue
        y = hm.simulate([beta, 0.0, 0.0, *MEANS, SD], shape=SHAPE, seed=seed_of(name))[1]
        record = {"part": "coverage", "dataset": k, "truth": truth}
        for method in ("surrogate", "exchange"):
            opts = {"fixed": FIELDS, "method": method, "bounds": {"coupling": BOUNDS}}
            if method == "surrogate":
                surrogate = surrogate or build_surrogate(hm.target("hidden", y, **opts),
                                                         seed=seed_of("coverage_surrogate"))
                opts["surrogate"] = surrogate
            post, sec = sample(hm.target("hidden", y, **opts), seed_of(f"{name}/{method}"))
            record[method] = summary(post, sec, truth)
        write(name, record)
        print(name, {m: record[m]["params"]["coupling"]["covers"]
                     for m in ("surrogate", "exchange")}, flush=True)


# -- real data --------------------------------------------------------------------------------
def run_menteith(n_steps: int) -> None:
    y = np.loadtxt(DATA / "menteith.txt", skiprows=1)
    q = 6
    # bayesImageS's sd prior: scale 20 with 5 degrees of freedom, an inverse gamma (2.5, 1000)
    hm = models.hidden(models.potts(q), models.emissions.gaussian(shared_sd=False,
                                                                  sd_prior=(2.5, 1000.0)))
    fixed = {f"field_{a}": 0.0 for a in range(1, q)}
    for method in ("pl", "surrogate", "pl_adjusted", "exchange"):
        name = f"menteith_{method}"
        if done(name):
            continue
        opts = {"fixed": fixed, "method": method, "bounds": {"coupling": (0.0, 3.0)}}
        record = {"part": "menteith", "method": method, "n_steps": n_steps}
        if method == "surrogate":
            t0 = time.perf_counter()
            s = build_surrogate(hm.target("hidden", y, **opts), seed=seed_of("menteith_surr"))
            record["surrogate_build_seconds"] = time.perf_counter() - t0
            record["surrogate"] = s.describe()
            opts["surrogate"] = s
        post, sec = sample(hm.target("hidden", y, **opts), seed_of(name), n_steps=n_steps,
                           burn_in=n_steps // 4)
        record.update(summary(post, sec))
        np.savez_compressed(TRIALS / f"{name}_labels.npz",
                            mode=post["label_mode"].values.astype(np.int8),
                            uncertainty=post["label_uncertainty"].values.astype(np.float32))
        write(name, record)
        print(name, record["params"]["coupling"], round(sec, 1), flush=True)


def run_laiche() -> None:
    x = np.loadtxt(DATA / "laiche.txt", skiprows=1, usecols=range(1, 26)).astype(np.int64)
    ising = models.MRF(models.lattice(4), 2, [models.Coupling()], name="ising_beta")
    for method, estimator, sampler in (("exchange", "likelihood", "exchange"),
                                       ("pl_adjusted", "pl_adjusted", "pmc"),
                                       ("pl", "pl", "pmc")):
        name = f"laiche_{method}"
        if done(name):
            continue
        kw = {"seed": seed_of(f"{name}/target")} if estimator == "pl_adjusted" else {}
        target = ising.target(estimator, x, bounds={"coupling": (0.0, 3.0)}, **kw)
        start = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", mrfpe.PosteriorWarning)
            post = mrfpe.sample(sampler, target, seed=seed_of(name))
        sec = time.perf_counter() - start
        mean = float(mrfpe.posterior.weighted_mean(post)[0])
        sd = float(np.sqrt(mrfpe.posterior.weighted_cov(post)[0, 0]))
        lo, hi = mrfpe.posterior.weighted_quantiles(post, [0.05, 0.95])[:, 0]
        record = {"part": "laiche", "method": method, "sampler": sampler, "seconds": sec,
                  "mean": mean, "sd": sd, "q05": float(lo), "q95": float(hi),
                  "reliable": int(post.attrs["diag_reliable"]),
                  "messages": str(post.attrs.get("diag_messages", ""))}
        write(name, record)
        print(name, record, flush=True)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--part", choices=("exact", "coverage", "menteith", "laiche"),
                   required=True)
    p.add_argument("--n-datasets", type=int, default=5)
    p.add_argument("--n-coverage", type=int, default=20)
    p.add_argument("--n-steps", type=int, default=3000)
    a = p.parse_args(argv)
    if a.part in ("menteith", "laiche") and not DATA.is_dir():
        sys.exit(f"the data folder {DATA} is missing (set MRFPE_DATA)")
    {"exact": lambda: run_exact(a.n_datasets), "coverage": lambda: run_coverage(a.n_coverage),
     "menteith": lambda: run_menteith(a.n_steps), "laiche": run_laiche}[a.part]()


if __name__ == "__main__":
    main()

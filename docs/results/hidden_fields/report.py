"""Tables and figures of the hidden-field study from its trial files (``run.py``): README.md.

    python docs/results/hidden_fields/report.py
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
TRIALS = HERE / "trials"
METHODS = ("exchange", "surrogate", "pl_adjusted", "pl")

INTRO = """# Hidden Markov random fields: exact checks, coverage and real data

Produced by `run.py` (trial files in `trials/`, one per data set or fit) and `report.py`
(this page). Methods for the MRF's parameters given the labels (`docs/models.md`,
"Hidden fields"): `exchange`, `surrogate` (pre-computed Gaussian synthetic likelihood),
`pl_adjusted` (calibrated PL at one labelling, approximate) and `pl` (pseudo-posterior).
Every run uses the `hidden` sampler's defaults (4 chains x 3000 sweeps, 1000 of burn-in)
unless a section says otherwise. Times are wall-clock on a shared two-core machine.
"""


def load(part: str) -> list[dict]:
    return [json.loads(p.read_text()) for p in sorted(TRIALS.glob(f"{part}_*.json"))]


def spread(values: list[float]) -> str:
    v = np.asarray(values, float)
    return f"{np.median(v):+.2f} [{v.min():+.2f}, {v.max():+.2f}]" if v.size else "-"


def exact_section(rows: list[dict]) -> list[str]:
    out = ["## Exact posteriors: 3-state hidden Potts on 6 x 40, emission known", "",
           "β's flat prior on (−0.5, 2); the exact posterior by the transfer matrix in product "
           "form on a 501-point grid. Per true β: the error of each method's posterior mean in "
           "exact sds and its sd ratio, median [min, max] over the data sets, and how many "
           "results said they were reliable.", "",
           "| true β | data sets | method | error (exact sd) | sd ratio | reliable | seconds "
           "(median) |", "|---|---|---|---|---|---|---|"]
    for beta in sorted({r["beta"] for r in rows}):
        sub = [r for r in rows if r["beta"] == beta]
        for m in METHODS:
            err = [(r[m]["params"]["coupling"]["mean"] - r["exact"]["mean"]) / r["exact"]["sd"]
                   for r in sub]
            ratio = [r[m]["params"]["coupling"]["sd"] / r["exact"]["sd"] for r in sub]
            rel = sum(r[m]["reliable"] for r in sub)
            sec = np.median([r[m]["seconds"] for r in sub])
            out.append(f"| {beta:.1f} | {len(sub)} | `{m}` | {spread(err)} | "
                       f"{spread(ratio).replace('+', '')} | {rel} of {len(sub)} | {sec:.0f} |")
    build = [r["surrogate_build_seconds"] for r in rows if "surrogate_build_seconds" in r]
    if build:
        out += ["", f"One surrogate served every data set (built in {build[0]:.0f} s)."]
    return [*out, ""]


def coverage_section(rows: list[dict]) -> list[str]:
    if not rows:
        return []
    names = list(rows[0]["truth"])
    out = ["## Coverage: emission unknown, β = 0.8", "",
           f"{len(rows)} data sets simulated on 6 x 40 (means 0, 1, 2, sd 0.6); means and sd "
           "free with the default priors, fields fixed at 0. How many 90 % intervals "
           "(5–95 % quantiles of the draws) cover the true value (binomial 90 % range for "
           f"{len(rows)}: {int(np.floor(0.9 * len(rows) - 1.645 * np.sqrt(0.09 * len(rows))))}"
           f"–{min(len(rows), int(np.ceil(0.9 * len(rows) + 1.645 * np.sqrt(0.09 * len(rows)))))})"
           ". The default run (4 chains x 3000 sweeps) is too short for R̂ ≤ 1.01 on most of "
           "these data sets with the emission unknown, and says so (the reliable column).", "",
           "| method | " + " | ".join(names) + " | reliable |",
           "|---|" + "---|" * (len(names) + 1)]
    for m in ("surrogate", "exchange"):
        cov = [sum(r[m]["params"][n]["covers"] for r in rows) for n in names]
        rel = sum(r[m]["reliable"] for r in rows)
        out.append(f"| `{m}` | " + " | ".join(f"{c} of {len(rows)}" for c in cov)
                   + f" | {rel} of {len(rows)} |")
    return [*out, ""]


def menteith_section(rows: list[dict]) -> list[str]:
    if not rows:
        return []
    out = ["## Lake of Menteith (100 x 100, 6 states, every parameter unknown)", "",
           "Marin & Robert (2014, ch. 8); bayesImageS's priors where ours can take them: β "
           "uniform on (0, 3), each sd² inverse gamma (2.5, 1000) (scale 20, 5 degrees of "
           "freedom); the means' prior is ours (normal, centred on the data's mean, sd its "
           "range; ordered), where bayesImageS centres each on its own value.", "",
           "| method | sweeps | β mean (sd) | means | sds | seconds | reliable | note |",
           "|---|---|---|---|---|---|---|---|"]
    by = {r["method"]: r for r in rows}
    for m in METHODS:
        if m not in by:
            continue
        r, p = by[m], by[m]["params"]
        means = ", ".join(f"{p[f'mean_{a}']['mean']:.1f}" for a in range(6))
        sds = ", ".join(f"{p[f'sd_{a}']['mean']:.1f}" for a in range(6))
        sec = r["seconds"] + r.get("surrogate_build_seconds", 0.0)
        note = (f"surrogate built in {r['surrogate_build_seconds']:.0f} s "
                f"({r['surrogate']['n_design']} design points)" if m == "surrogate" else
                f"{r['attrs'].get('aux_sweeps', 0):.0f} auxiliary sweeps" if m == "exchange"
                else "")
        out.append(f"| `{m}` | 4 x {r['n_steps']} | "
                   f"{p['coupling']['mean']:.3f} ({p['coupling']['sd']:.3f}) | "
                   f"{means} | {sds} | {sec:.0f} | {r['reliable']} | {note} |")
    if "exchange" in by and "surrogate" in by:
        per = {m: by[m]["seconds"] / by[m]["n_steps"] for m in ("exchange", "surrogate")}
        ratio = by["exchange"]["seconds"] / (by["surrogate"]["seconds"]
                                             + by["surrogate"]["surrogate_build_seconds"])
        out += ["", f"Per sweep, exchange took {per['exchange'] / per['surrogate']:.0f} x the "
                    f"surrogate's sampling; a whole exchange run {ratio:.1f} x a whole surrogate "
                    "run, its build included "
                    "(bayesImageS reports its surrogate about 200 x faster than its approximate "
                    "exchange with 200 Swendsen–Wang sweeps per auxiliary draw)."]
    if (HERE / "menteith.png").exists():
        out += ["", "![Menteith: image, segmentation and uncertainty](menteith.png)"]
    msgs = {m: "; ".join(by[m]["messages"].splitlines()) for m in by if by[m]["messages"]}
    out += ["", *(f"- `{m}`: {msg}" for m, msg in msgs.items())]
    return [*out, ""]


def laiche_section(rows: list[dict]) -> list[str]:
    if not rows:
        return []
    out = ["## Laiche presence grid (25 x 25, observed)", "",
           "Ising model in Potts form, `β Σ [x_i = x_j]` over 4-neighbour pairs (β only, as "
           "Marin & Robert), β uniform on (0, 3).", "",
           "| method | sampler | β mean (sd) | 90 % interval | seconds | reliable |",
           "|---|---|---|---|---|---|"]
    for r in sorted(rows, key=lambda r: METHODS.index(r["method"])):
        out.append(f"| `{r['method']}` | {r['sampler']} | {r['mean']:.3f} ({r['sd']:.3f}) | "
                   f"{r['q05']:.3f}–{r['q95']:.3f} | {r['seconds']:.1f} | {r['reliable']} |")
    out += ["", "`pl` is exp(PL), a pseudo-posterior whatever its sampler's verdict on its "
                "Monte Carlo error: its mean and spread are not the posterior's."]
    return [*out, ""]


def figure(rows: list[dict]) -> None:
    """The Menteith image, the surrogate's segmentation and its per-pixel uncertainty."""
    import os

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = TRIALS / "menteith_surrogate_labels.npz"
    data = Path(os.environ.get("MRFPE_DATA", HERE.parents[3] / "shared" / "data"))
    if not labels.exists() or not (data / "menteith.txt").exists():
        return
    y = np.loadtxt(data / "menteith.txt", skiprows=1)
    z = np.load(labels)
    fig, ax = plt.subplots(1, 3, figsize=(11, 3.6))
    for a, img, title, cmap in ((ax[0], y, "image", "gray"),
                                (ax[1], z["mode"], "segmentation (surrogate)", "viridis"),
                                (ax[2], z["uncertainty"], "1 - max p(x_i | y)", "magma")):
        im = a.imshow(img, cmap=cmap)
        a.set_title(title)
        a.axis("off")
        fig.colorbar(im, ax=a, fraction=0.046)
    fig.tight_layout()
    fig.savefig(HERE / "menteith.png", dpi=90)


def main() -> None:
    figure(load("menteith"))
    lines = [INTRO, *exact_section(load("exact")), *coverage_section(load("coverage")),
             *menteith_section(load("menteith")), *laiche_section(load("laiche"))]
    (HERE / "README.md").write_text("\n".join(lines).rstrip() + "\n")


if __name__ == "__main__":
    main()

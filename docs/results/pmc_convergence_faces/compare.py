"""PMC (II) from the face-to-face grid against the cell-centred grid, paired scene by scene.

Each trial here has a twin in ``../pmc_convergence/trials`` with the same scene and run seeds
(the study derives both from the study seed, the repetition and the cell, not from the
options), so the difference between the two is the initial grid alone. Prints, per column and
N, the mean best-so-far MAP distance to the truth at iterations 1, 5, 10 and 20 for the thesis,
the faces grid and the centres grid, and the paired mean difference faces − centres at
iterations 1 and 20 with its standard error. Usage (from the repository root)::

    python docs/results/pmc_convergence_faces/compare.py
"""

from pathlib import Path

import numpy as np
import xarray as xr

from mrfpe.experiments._thesis import PMC_TABLES

HERE = Path(__file__).resolve().parent
CENTRES = HERE.parent / "pmc_convergence" / "trials"
ITERATIONS = (1, 5, 10, 20)


def load(path: Path) -> np.ndarray:
    """(n_samples, iteration) best-so-far MAP → truth of the trial's PMC (II) runs."""
    with xr.open_dataset(path) as ds:
        return ds["map_to_truth"].sel(variant="thesis2").values


def main() -> None:
    columns: dict[tuple[str, int], list[Path]] = {}
    for path in sorted((HERE / "trials").glob("*.nc")):
        cell = dict(kv.split("=") for kv in path.stem.split(",")[:2])
        columns.setdefault((cell["brdf"], int(cell["n_labels"])), []).append(path)
    cols = " | ".join(f"it {i}" for i in ITERATIONS)
    print(f"| model, labels | N | grid | trials | {cols} | faces − centres, it 1 | it 20 |")
    print("|---|---|---|---|" + "---|" * len(ITERATIONS) + "---|---|")
    for (brdf, labels), paths in columns.items():
        faces = np.array([load(p) for p in paths])
        centres = np.array([load(CENTRES / p.name) for p in paths])
        for j, n in enumerate((1000, 125, 64)):
            ref = PMC_TABLES[(brdf, labels, n)][0]
            diff = faces[:, j] - centres[:, j]
            se = diff.std(axis=0, ddof=1) / np.sqrt(len(paths))
            rows = (("thesis", [ref[i - 1] for i in ITERATIONS], ""),
                    ("faces", [faces[:, j, i - 1].mean() for i in ITERATIONS],
                     f"{diff[:, 0].mean():+.3f} ± {se[0]:.3f} | {diff[:, -1].mean():+.3f} ± "
                     f"{se[-1]:.3f}"),
                    ("centres", [centres[:, j, i - 1].mean() for i in ITERATIONS], ""))
            for name, vals, d in rows:
                count = "100 runs" if name == "thesis" else str(len(paths))
                cells = " | ".join(f"{v:.3f}" for v in vals)
                print(f"| {brdf}, {labels} | {n} | {name} | {count} | {cells} | {d or ' | '} |")


if __name__ == "__main__":
    main()

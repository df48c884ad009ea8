"""Record in the committed trials that their PMC (II) runs started from the cell-centred grid.

Until 2026-12-02 the thesis variants of PMC started from the cell centres of the evenly spaced
grid (``initial="grid"``); since then they start, by default, from the grid from face to face
(``initial="grid_faces"``, the reading under which PMC (II) reproduces Table 7.1's N = 125 and
64 columns: ``pmc_convergence_faces/``). The trials committed before that were computed with
the old default but record no ``initial``, so the new code would read them as face-grid runs.
This script writes the option they ran with into each trial's ``trial_config`` and
``study_config`` attributes and the result directory's ``config.json``, recomputes the
``config_hash`` (so a resume or a report must ask for that option, and a default run cannot mix
new trials into them) and adds a ``pinned_utc`` attribute. The data are untouched. Idempotent.
Usage (from the repository root): ``python docs/results/pin_initial_grid.py``.
"""

import json
from datetime import UTC, datetime
from pathlib import Path

import netCDF4

from mrfpe.study import config_hash, get
from mrfpe.study.config import canonical

HERE = Path(__file__).resolve().parent
THESIS_VARIANTS = ("thesis2", "thesis2_literal", "thesis1")


def pin_pmc_options(cfg: dict) -> bool:
    """``pmc_convergence``: the thesis variants' options under their names."""
    opts = cfg["pmc_options"]
    changed = False
    for variant in cfg["variants"]:
        if variant in THESIS_VARIANTS and "initial" not in opts.get(variant, {}) \
                and "initial" not in opts:
            opts[variant] = {**opts.get(variant, {}), "initial": "grid"}
            changed = True
    return changed


def pin_pmc(cfg: dict) -> bool:
    """``posterior_slices``, ``classification``: the one ``pmc`` options object."""
    if cfg["pmc"].get("variant") in THESIS_VARIANTS and "initial" not in cfg["pmc"]:
        cfg["pmc"]["initial"] = "grid"
        return True
    return False


DIRECTORIES = {"pmc_convergence": pin_pmc_options, "posterior_slices": pin_pmc,
               "classification": pin_pmc}


def main() -> None:
    now = datetime.now(UTC).isoformat(timespec="seconds")
    for name, pin in DIRECTORIES.items():
        study, out = get(name), HERE / name
        manifest = out / "config.json"
        meta = json.loads(manifest.read_text())
        if pin(meta["config"]):
            manifest.write_text(json.dumps(meta, indent=2, sort_keys=True) + "\n")
        n = 0
        for path in sorted((out / "trials").glob("*.nc")):
            with netCDF4.Dataset(path, "a") as nc:
                tcfg = json.loads(nc.getncattr("trial_config"))
                scfg = json.loads(nc.getncattr("study_config"))
                if not pin(tcfg):
                    continue
                pin(scfg)
                nc.setncattr("trial_config", canonical(tcfg))
                nc.setncattr("study_config", canonical(scfg))
                nc.setncattr("config_hash", config_hash(study, tcfg))
                nc.setncattr("pinned_utc", f"{now}: initial='grid' recorded "
                                           "(docs/results/pin_initial_grid.py)")
                n += 1
        print(f"{name}: {n} trial files pinned")


if __name__ == "__main__":
    main()

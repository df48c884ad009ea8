"""One-off (2026-12-01): drop the summary-only settings from the trial files' config and hash.

The classification trials were computed while ``grid_power``, ``agmmp_sigmas`` and
``extra_distances`` were still part of every trial's config, although ``trial()``
reads none of them. Since they are declared ``summary_only`` (mrfpe.study.Setting),
a trial's config leaves them out, so this rewrites each file's ``trial_config`` and
``config_hash`` attributes to what the runner now writes. It checks first that the
stored hash is the hash of the stored config under the old rule, and that nothing
else differs from the study's current trial config. Idempotent.

    cd docs/results/classification && python readings/migrate_summary_only.py trials
"""

import json
import sys
from pathlib import Path

import netCDF4

from mrfpe.study import config_hash, get, resolve_config, tasks
from mrfpe.study.config import canonical

study = get("classification")
want = {t.stem: t for t in tasks(study, resolve_config(study))}
n = 0
for path in sorted(Path(sys.argv[1]).glob("*.nc")):
    task = want[path.stem]
    with netCDF4.Dataset(path, "a") as nc:
        old = json.loads(nc.getncattr("trial_config"))
        if nc.getncattr("config_hash") == task.hash:
            continue
        assert config_hash(study, old) == nc.getncattr("config_hash"), path
        kept = {k: v for k, v in old.items() if k not in study.summary_keys}
        assert canonical(kept) == canonical(task.config), (
            path, [k for k in {*kept, *task.config} if kept.get(k) != task.config.get(k)])
        nc.setncattr("trial_config", canonical(task.config))
        nc.setncattr("config_hash", task.hash)
        n += 1
print(f"rewrote {n} trial file(s)")

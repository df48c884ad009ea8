"""The committed trial files under docs/results are what their attributes say they are."""

import json
from pathlib import Path
from types import SimpleNamespace

import pytest

from mrfpe.netcdf import read_attrs
from mrfpe.study import config_hash

RESULTS = Path(__file__).resolve().parents[2] / "docs" / "results"
#: Study outputs: a ``trials/`` folder beside the study's ``config.json`` (results scripts that
#: are not studies, such as ``calibrated_classification/run.py``, write neither).
TRIAL_DIRS = sorted({p.parent for p in RESULTS.glob("**/trials/*.nc")
                     if (p.parent.parent / "config.json").exists()})


@pytest.mark.skipif(not TRIAL_DIRS, reason="no committed results in this checkout")
@pytest.mark.parametrize("trials", TRIAL_DIRS, ids=lambda p: str(p.relative_to(RESULTS)))
def test_each_trial_hash_is_its_recorded_config(trials):
    # A resume or a report trusts config_hash; it must be the hash of the recorded trial
    # config (docs/results/pin_initial_grid.py rewrote both for the cell-centred PMC runs).
    for path in sorted(trials.glob("*.nc")):
        attrs = read_attrs(path, "trial")
        study = SimpleNamespace(name=attrs["study"], version=int(attrs["study_version"]))
        tcfg = json.loads(attrs["trial_config"])
        assert config_hash(study, tcfg) == attrs["config_hash"], path.name

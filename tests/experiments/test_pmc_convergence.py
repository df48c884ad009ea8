"""pmc_convergence: options per variant."""

import pytest

from mrfpe.experiments.pmc_convergence import check_config, variant_options
from mrfpe.study import get, resolve_config


def test_options_for_every_variant_or_for_one():
    opts = {"sigma0": 0.05, "thesis2": {"initial": "grid", "sigma0": 0.1}}
    assert variant_options(opts, "thesis2") == {"sigma0": 0.1, "initial": "grid"}
    assert variant_options(opts, "mixture") == {"sigma0": 0.05}
    assert variant_options({}, "thesis2") == {}


def test_per_variant_options_are_checked():
    study = get("pmc_convergence")
    cfg = resolve_config(study, quick=True,
                         overrides=['pmc_options={"thesis2": {"initial": "grid"}}'])
    check_config(cfg)  # valid: thesis2 from the cell centres, mixture untouched
    with pytest.raises(ValueError, match=r"pmc_options\['thesis2'\] must be an object"):
        resolve_config(study, quick=True, overrides=['pmc_options={"thesis2": "grid"}'])
    with pytest.raises(ValueError, match="initial"):  # an option the variant refuses
        resolve_config(study, quick=True,
                       overrides=['pmc_options={"mixture": {"initial": "faces"}}'])

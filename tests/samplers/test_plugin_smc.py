"""The third-party SMC plugin (plugins/mrfpe-smc) is found through its entry point."""

import ast
import importlib.metadata as md
from pathlib import Path

import numpy as np

import mrfpe
from mrfpe.samplers import available, registry, table
from mrfpe.testing import TwoModes

PLUGIN = Path(__file__).resolve().parents[2] / "plugins" / "mrfpe-smc"


def test_discovered_through_the_entry_point():
    eps = [ep for ep in md.entry_points(group="mrfpe.samplers") if ep.name == "smc"]
    assert eps, "mrfpe-smc is not installed: pip install ./plugins/mrfpe-smc"
    assert eps[0].value == "mrfpe_smc:AdaptiveTemperingSMC"
    info = registry.entries()["smc"]
    assert info.ok and info.package == "mrfpe-smc" and info.version == "0.1.0"
    assert "smc" in available()
    assert "mrfpe-smc" in table()


def test_runs_through_the_front_door():
    post = mrfpe.sample("smc", TwoModes(), seed=0, n_particles=300)
    assert post.attrs["sampler"] == "smc"
    np.testing.assert_allclose(post["map_theta"].values[-1], TwoModes.high, atol=0.02)


def test_uses_only_public_api():
    tree = ast.parse((PLUGIN / "mrfpe_smc" / "__init__.py").read_text())
    mods = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
    mods |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    ours = {m for m in mods if m.split(".")[0] == "mrfpe"}
    assert ours <= {"mrfpe.posterior", "mrfpe.samplers", "mrfpe.samplers.kit",
                    "mrfpe.samplers.base"}, ours
    names = {f"{n.module}.{a.name}" for n in ast.walk(tree)
             if isinstance(n, ast.ImportFrom) and (n.module or "").startswith("mrfpe")
             for a in n.names}
    assert not any(part.startswith("_") for m in ours | names for part in m.split(".")), names

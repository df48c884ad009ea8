"""Old module paths of the BRDF wing's modules still import, warning and naming the new place."""

from __future__ import annotations

import importlib
import sys
import warnings

import pytest

from mrfpe._moved import MOVED, new_name

#: Every old module path (the prefixes' submodules spelled out).
OLD_PATHS = sorted([k for k in MOVED if not k.endswith(".")] + [
    "mrfpe.engine.lean", "mrfpe.engine.plan", "mrfpe.engine.evaluate", "mrfpe.stereo.match",
    "mrfpe.stereo.calibration"])


@pytest.mark.parametrize("old", OLD_PATHS)
def test_old_path_warns_and_gives_the_module_at_its_new_place(old, monkeypatch):
    new = new_name(old)
    module = importlib.import_module(new)
    for name in [m for m in sys.modules if m == old or m.startswith(old + ".")]:
        monkeypatch.delitem(sys.modules, name)  # import it afresh; restored after the test
    with pytest.warns(DeprecationWarning, match=rf"{old} has moved to {new}"):
        alias = importlib.import_module(old)
    assert alias is module
    assert module.__spec__.name == new  # the alias did not take the module's own spec


def test_from_import_of_an_old_path_gives_the_same_objects(monkeypatch):
    monkeypatch.delitem(sys.modules, "mrfpe.synthetic", raising=False)
    with pytest.warns(DeprecationWarning, match="mrfpe.brdf.synthetic"):
        from mrfpe.synthetic import make_scene
    from mrfpe.brdf.synthetic import make_scene as new

    assert make_scene is new


def test_new_paths_import_without_a_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        for new in {new_name(old) for old in OLD_PATHS}:
            importlib.import_module(new)


def test_new_name_maps_prefixes_and_leaves_the_rest():
    assert new_name("mrfpe.engine.fastmath") == "mrfpe.fastmath"  # an exception to its prefix
    assert new_name("mrfpe.engine.lean_nodes") == "mrfpe.brdf.engine.lean_nodes"
    assert new_name("mrfpe.targets.potts") == "mrfpe.models.short_forms"
    assert new_name("mrfpe.targets.base") is None
    assert new_name("mrfpe.brdf") is None


def test_root_scene_warns():
    import mrfpe
    from mrfpe.brdf.scene import Scene

    with pytest.warns(DeprecationWarning, match="mrfpe.brdf.Scene"):
        assert mrfpe.Scene is Scene


def test_the_door_by_name_serves_the_wing_without_a_warning():
    from mrfpe.brdf.synthetic import make_scene
    from mrfpe.brdf.targets.pseudolikelihood import PL
    from mrfpe.targets import get, names

    scene = make_scene("ward", [0.5, 0.3, 0.2], shape=(4, 4), n_labels=3, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        assert isinstance(get("pl", scene), PL)
    assert {"pl", "pl2", "pl3", "pls", "fit", "pml", "potts", "potts_exact"} <= set(names())

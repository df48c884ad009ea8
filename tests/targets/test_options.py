"""Declarative target options and the honest get(name, data, **options)."""

from __future__ import annotations

import numpy as np
import pytest

from mrfpe.brdf.synthetic import make_scene
from mrfpe.targets import data_kind, describe, get, names, options
from mrfpe.targets.options import Option, resolve_options


@pytest.fixture(scope="module")
def scene():
    return make_scene(brdf="ward", theta=[0.6, 0.5, 0.2], shape=(2, 2), n_labels=3, seed=0)


def _data(name, scene):
    return scene if data_kind(name) == "scene" else np.zeros((3, 3), dtype=int)


@pytest.mark.parametrize("name", names())
def test_every_target_declares_options(name):
    specs = options(name)
    assert specs and all(isinstance(o, Option) and o.help and o.type for o in specs)
    assert len({o.name for o in specs}) == len(specs)
    for o in specs:  # every default passes its own check
        o.resolve(o.default)
    assert all(o.name in describe(name) for o in specs)


@pytest.mark.parametrize("name", names())
def test_unknown_option_lists_valid_ones_with_nearest_match(name, scene):
    first = options(name)[0].name
    with pytest.raises(ValueError) as exc:
        get(name, _data(name, scene), **{first + "x": 1})
    msg = str(exc.value)
    assert f"did you mean {first!r}" in msg
    assert "valid options: " + ", ".join(o.name for o in options(name)) in msg


@pytest.mark.parametrize("name", names())
def test_wrong_data_kind_is_named(name, scene):
    wrong = np.zeros((3, 3), dtype=int) if data_kind(name) == "scene" else scene
    with pytest.raises(ValueError, match="data must be"):
        get(name, wrong)


def test_bad_values_name_the_option(scene):
    for opts, word in [({"sigma_b": True}, "sigma_b"), ({"dtype": "float16"}, "dtype"),
                       ({"progress": "yes"}, "progress"), ({"data_term": 1}, "data_term")]:
        with pytest.raises(ValueError, match=word):
            get("pl", scene, **opts)
    with pytest.raises(ValueError, match="smoothness_e"):
        get("pl2", scene, smoothness_e=1.0)
    with pytest.raises(ValueError, match="smoothness"):
        get("pl2", scene, smoothness="no")
    with pytest.raises(ValueError, match="prior_weight"):
        get("pls", scene, prior_weight=-1)
    with pytest.raises(ValueError, match="n_states"):
        get("potts", np.zeros((3, 3), dtype=int), n_states=1)
    with pytest.raises(ValueError, match="did you mean 'pls'"):
        get("plss", scene)


def test_resolve_options_fills_defaults():
    specs = (Option("a", "int", 1, lambda n, v: int(v), "a"),)
    assert resolve_options("t", specs, {}) == {"a": 1}
    assert resolve_options("t", specs, {"a": "3"}) == {"a": 3}
    with pytest.raises(ValueError, match=r"t: unknown option\(s\) 'b'; valid options: a"):
        resolve_options("t", specs, {"b": 2})


def test_single_label_scene_is_rejected_by_pseudolikelihoods():
    from mrfpe.brdf.scene import Scene

    sc = make_scene(brdf="ward", theta=[0.6, 0.5, 0.2], shape=(2, 2), n_labels=2, seed=0)
    one = Scene(image=sc.image, camera=sc.camera, light=sc.light,
                label_ranges=sc.label_ranges[..., :1], observed_labels=np.zeros((3, 3), int),
                brdf="ward", range_prior=sc.range_prior[..., :1])
    for name in ("pl", "pls", "pl2"):
        with pytest.raises(ValueError, match="n_labels >= 2"):
            get(name, one)
    get("fit", one)  # the image fit is meaningful with one label

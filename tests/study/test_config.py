"""``--set`` parsing and coercion (property-based), declared settings and their errors."""

from __future__ import annotations

import json
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mrfpe import cli
from mrfpe import study as S
from mrfpe.experiments import importance_sampling as toy
from mrfpe.study.config import coerce_like, parse_assignment, parse_value

from .. import _processes as procs

json_scalars = st.none() | st.booleans() | st.integers(-10**12, 10**12) | \
    st.floats(allow_nan=False, allow_infinity=False) | st.text(max_size=20)
json_values = st.recursive(json_scalars, lambda inner: st.lists(inner, max_size=4)
                           | st.dictionaries(st.text(max_size=8), inner, max_size=4),
                           max_leaves=10)
keys = st.text(st.characters(blacklist_characters="=", blacklist_categories=("Cs",)),
               min_size=1, max_size=20).filter(lambda k: k.strip() == k and k)


@given(keys, json_values)
def test_json_values_round_trip(key, value):
    assert parse_assignment(f"{key}={json.dumps(value)}") == (key, value)


@given(keys, st.text(max_size=30))
def test_the_value_is_everything_after_the_first_equals(key, raw):
    k, v = parse_assignment(f"{key}={raw}")
    assert k == key
    try:
        assert v == json.loads(raw) or (isinstance(v, float) and math.isnan(v))
    except json.JSONDecodeError:
        assert v == raw  # not JSON: kept as the string


@given(st.text(max_size=30))
def test_parse_value_never_raises(raw):
    parse_value(raw)


@given(st.text(st.characters(blacklist_characters="=", blacklist_categories=("Cs",)),
               max_size=20))
def test_an_item_without_equals_is_a_value_error(item):
    with pytest.raises(ValueError, match="key=value"):
        parse_assignment(item)
    with pytest.raises(ValueError, match=r"^--param: expected key=value"):
        cli.parse_assignments([item], "--param")


@given(json_values, json_values)
def test_coercion_returns_the_defaults_type_or_raises_value_error(default, value):
    try:
        out = coerce_like("k", value, default)
    except ValueError as exc:
        assert str(exc).startswith("setting 'k' expects")
        return
    if default is None or value is None:
        assert out == value
    elif isinstance(default, bool):
        assert out is value
    elif isinstance(default, int):
        assert isinstance(out, int) and not isinstance(out, bool) and out == value
    elif isinstance(default, float):
        assert isinstance(out, float) and out == value
    else:
        assert type(out) is type(default)


@settings(max_examples=200)
@given(st.sampled_from(sorted(toy.STUDY.config)), st.text(max_size=30))
def test_resolve_config_accepts_or_gives_one_line_value_error(key, raw):
    try:
        cfg = S.resolve_config(toy.STUDY, overrides=[f"{key}={raw}"])
    except ValueError as exc:
        assert "\n" not in str(exc)
        return
    value = cfg[key]
    assert type(value) is type(toy.STUDY.config[key])


def test_unknown_setting_names_the_nearest():
    with pytest.raises(ValueError, match=r"unknown setting 'sigm'.*did you mean 'sigma'.*"
                                         r"settings: mu, n_samples"):
        S.resolve_config(toy.STUDY, overrides=["sigm=1"])


def test_declared_settings_check_types_choices_and_values():
    pmc = S.get("pmc_convergence")
    assert pmc.setting("variants").valid_choices() == ("mixture", "thesis2", "thesis2_literal",
                                                        "thesis1")
    with pytest.raises(ValueError, match="'bogus' is not one of mixture, thesis2, "
                                         "thesis2_literal, thesis1"):
        S.resolve_config(pmc, overrides=['variants=["bogus"]'])
    with pytest.raises(ValueError, match="setting 'brdf': 'wrd' is not one of"):
        S.resolve_config(pmc, overrides=["brdf=wrd"])
    with pytest.raises(ValueError, match="setting 'n_labels': must be > 0"):
        S.resolve_config(pmc, overrides=["n_labels=[0]"])
    with pytest.raises(ValueError, match="sampler 'pmc'"):  # study-level check: option
        S.resolve_config(pmc, overrides=['pmc_options={"nope": 1}'])
    with pytest.raises(ValueError, match="no surface type for lambertian"):
        S.resolve_config(pmc, overrides=['brdf=["lambertian"]'])
    with pytest.raises(ValueError, match=r"setting 'target_options': pls: unknown "
                                         r"option\(s\) 'bogus'; valid options:"):
        S.resolve_config(pmc, overrides=['target_options={"bogus": 1}'])
    with pytest.raises(ValueError, match="setting 'runs'"):
        S.resolve_config(S.get("target_bias"), overrides=['runs={"x": {"sampler": "nope"}}'])


def test_every_builtin_setting_has_help_and_valid_defaults():
    for study in S.available().values():
        for setting in study.settings:
            assert setting.help, (study.name, setting.name)
        S.resolve_config(study)
        S.resolve_config(study, quick=True)


def test_settings_and_config_must_agree():
    kw = dict(name="x", doc="X.\n\nFull run: 1 s.", trial=toy.trial, summarise=toy.summarise)
    st_ = S.Study(**kw, settings=[S.Setting("a", 1, "an a")], config={"n_trials": 1, "seed": 0})
    assert st_.config == {"a": 1, "n_trials": 1, "seed": 0}
    with pytest.raises(ValueError, match="disagrees"):
        S.Study(**kw, settings=[S.Setting("a", 1)], config={"n_trials": 1, "seed": 0, "a": 2})


def test_the_library_does_not_import_the_command_line():
    code = ("import sys; from mrfpe import study as S; "
            "import mrfpe.experiments.pmc_convergence as m; "
            "S.resolve_config(m.STUDY, overrides=['n_labels=20']); "
            "assert 'mrfpe.cli' not in sys.modules, 'mrfpe.study imported mrfpe.cli'")
    procs.python(code)

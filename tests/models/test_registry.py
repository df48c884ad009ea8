"""Model plugins that do not build a model: listed broken, and named by every error."""

from __future__ import annotations

import os
import sys
import warnings

import pytest

import mrfpe.models as models
from mrfpe import cli
from mrfpe._plugins import PluginError, Registry
from mrfpe.models.registry import check_model_factory, validate_model

from .. import _processes as procs
from .._dists import make_dist, on_sys_path, unique

FACTORIES = """
    import mrfpe.models as models

    def fortytwo():
        return 42

    def raises():
        raise RuntimeError("no lattice\\nhere")

    def good(n_states=2):
        return models.potts(n_states)

    def picky(n_states=2):
        if n_states != 2:
            raise RuntimeError("only two states")
        return models.potts()

    def liar(n_states=2):
        return models.potts() if n_states == 2 else 42
"""


@pytest.fixture
def site(tmp_path, monkeypatch):
    yield from on_sys_path(tmp_path, monkeypatch)


@pytest.fixture
def bad_models(site, request):
    mod = unique(request, "bad_models")
    make_dist(site, "badmodels", {mod: FACTORIES}, {"mrfpe.models": {
        n: f"{mod}:{n}" for n in ("fortytwo", "raises", "good", "picky", "liar")}})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        models.registry.entries(refresh=True)
    return mod


def test_a_factory_returning_42_or_raising_is_listed_broken(bad_models, capsys):
    broken = models.registry.errors()
    assert broken["fortytwo"] == ("TypeError: fortytwo() returned int 42, not an "
                                  "mrfpe.models.Model")
    assert broken["raises"] == "TypeError: raises() raised RuntimeError: no lattice here"
    assert {"good", "picky", "liar", "potts"} <= set(models.names())
    assert cli.main(["models"]) == 0
    rows = {line.split()[0]: line for line in capsys.readouterr().out.splitlines()[2:]
            if line[:1].strip()}
    assert "BROKEN: TypeError: fortytwo() returned int 42" in rows["fortytwo"]
    assert "BROKEN: TypeError: raises() raised RuntimeError" in rows["raises"]
    assert "BROKEN" not in rows["good"] and "BROKEN" not in rows["potts"]


@pytest.mark.parametrize("name", ["fortytwo", "raises"])
def test_get_of_a_broken_factory_is_one_line_naming_the_plugin(bad_models, name):
    with pytest.raises(ValueError) as err:
        models.get(name)
    msg = str(err.value)
    assert msg.startswith(f"model plugin {name!r} ({bad_models}:{name}, package badmodels "
                          f"1.0) is broken: TypeError: {name}() ")
    assert "\n" not in msg


def test_a_factory_failing_on_its_settings_is_named(bad_models):
    assert models.get("good", n_states=3).n_states == 3
    assert models.get("picky").n_states == 2
    with pytest.raises(PluginError, match=r"^model plugin 'picky' \(.*:picky, package "
                                          r"badmodels 1.0\) failed: RuntimeError: only two"):
        models.get("picky", n_states=3)
    with pytest.raises(TypeError, match=r"^model plugin 'liar' \(.*:liar, package badmodels "
                                        r"1.0\) returned int 42, not an mrfpe.models.Model$"):
        models.get("liar", n_states=3)
    with pytest.raises(ValueError, match="model 'good' takes n_states; got colours"):
        models.get("good", colours=3)


def test_a_built_in_factory_error_is_left_as_it_is():
    """mrfpe's own errors are not dressed up as a plugin's."""
    with pytest.raises(ValueError) as err:
        models.get("potts", n_states=1)
    assert "plugin" not in str(err.value)


def test_check_model_factory():
    check_model_factory(models.potts)
    check_model_factory(lambda: models.ising())
    with pytest.raises(TypeError, match=r"returned NoneType None, not"):
        check_model_factory(lambda: None)
    with pytest.raises(TypeError, match=r"raised ZeroDivisionError"):
        check_model_factory(lambda: 1 / 0)


def test_a_lookup_builds_only_the_model_asked(site, request):
    """A fresh registry: ``get`` imports and builds only the entry point of its name."""
    mod = unique(request, "counting_models")
    make_dist(site, "counting", {mod: """
        import mrfpe.models as models
        BUILT = []

        def one():
            BUILT.append("one")
            return models.potts()

        def two():
            BUILT.append("two")
            return models.potts()
    """}, {"mrfpe.models": {"one": f"{mod}:one", "two": f"{mod}:two"}})
    other = unique(request, "unrelated_models")
    make_dist(site, "unrelated", {other: "raise SystemExit('imported')\n"},
              {"mrfpe.models": {"unrelated": f"{other}:f"}})
    reg = Registry("mrfpe.models", "model", validate_model, check_model_factory)
    assert reg.get("one")().n_states == 2
    assert sys.modules[mod].BUILT == ["one", "one"]  # discovery's check, then the call
    assert other not in sys.modules
    assert reg.get("potts") is models.potts


def test_a_factory_ending_the_process_when_called_is_caught_by_the_probe(tmp_path):
    """The discovery check runs in the probe process first: a factory that calls
    ``os._exit`` (with no arguments) is listed broken, not fatal to ``mrfpe models``."""
    make_dist(tmp_path, "killer", {"killer_model": """
        import os

        def build():
            os._exit(9)
    """}, {"mrfpe.models": {"killer": "killer_model:build"}})
    done = procs.run([sys.executable, "-m", "mrfpe", "models"], check=False, timeout=120,
                     env={**os.environ, "PYTHONPATH": str(tmp_path)})
    assert done.returncode == 0, done.stderr
    row = next(line for line in done.stdout.splitlines() if line.startswith("killer "))
    assert "BROKEN: loading it ended the process (exit status 9)" in row
    assert "potts" in done.stdout

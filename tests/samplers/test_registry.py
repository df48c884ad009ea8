"""The sampler registry: discovery, validation, broken plugins, CLI listing."""

import importlib.metadata as md
import sys
import types
import warnings

import numpy as np
import pytest

import mrfpe._plugins as plugins
import mrfpe.samplers as samplers
from mrfpe import cli
from mrfpe.samplers.registry import validate_sampler

from .. import _processes as procs

BUILTINS = {"pmc", "sir", "ppf", "mh", "dw_q", "dw_r", "emcee", "lm_multiseed",
            "nlopt_multiseed"}


class Good:
    """A good fake sampler."""

    def __init__(self, n: int = 3):
        self.n = n

    def run(self, target, *, seed=None, progress=False, callback=None):
        return None


class NeedsArgs(Good):
    def __init__(self, n):
        self.n = n


class NoKeywords:
    def run(self, target, seed):
        return None


def not_a_class(target, *, seed=None, progress=False, callback=None):
    return None


@pytest.fixture
def fake_plugins(monkeypatch):
    mod = types.ModuleType("fake_mrfpe_plugin")
    for obj in (Good, NeedsArgs, NoKeywords, not_a_class):
        setattr(mod, obj.__name__, obj)
    monkeypatch.setitem(sys.modules, "fake_mrfpe_plugin", mod)
    real = md.entry_points(group="mrfpe.samplers")
    fakes = [md.EntryPoint(n, v, "mrfpe.samplers") for n, v in [
        ("fake_good", "fake_mrfpe_plugin:Good"),
        ("fake_import", "no_such_module_for_mrfpe_tests:Thing"),
        ("fake_args", "fake_mrfpe_plugin:NeedsArgs"),
        ("fake_kw", "fake_mrfpe_plugin:NoKeywords"),
        ("fake_func", "fake_mrfpe_plugin:not_a_class"),
        ("pmc", "fake_mrfpe_plugin:Good"),  # duplicates a built-in name
    ]]

    def entry_points(**kw):
        if kw.get("group") == "mrfpe.samplers":
            return [*real, *fakes]
        return md.entry_points(**kw)

    monkeypatch.setattr(plugins.md, "entry_points", entry_points)
    with warnings.catch_warnings():  # the warning itself is tested below
        warnings.simplefilter("ignore", RuntimeWarning)
        samplers.registry.entries(refresh=True)
    yield
    monkeypatch.undo()
    samplers.registry.entries(refresh=True)


def test_builtins_are_registered():
    assert BUILTINS <= set(samplers.registry.entries())
    assert {"pmc", "sir", "ppf"} <= set(samplers.available())
    info = samplers.registry.entries()["pmc"]
    assert info.package == "mrfpe" and info.version and "Population Monte Carlo" in info.description


def test_broken_plugins_are_reported_not_raised(fake_plugins):
    avail = samplers.available()
    assert "fake_good" in avail and "pmc" in avail
    broken = samplers.broken()
    assert "ModuleNotFoundError" in broken["fake_import"]
    assert "no arguments" in broken["fake_args"] and "n" in broken["fake_args"]
    assert "seed" in broken["fake_kw"]
    assert "must be a class" in broken["fake_func"]
    dup = [k for k in broken if k.startswith("pmc [")]
    assert dup and "duplicate" in broken[dup[0]]
    assert samplers.get("pmc").__name__ == "PMC"  # the first registration keeps the name
    table = samplers.table()
    assert "BROKEN" in table and "fake_good" in table and "A good fake sampler." in table
    with pytest.raises(ValueError, match="broken"):
        samplers.get("fake_import")


def test_cli_survives_broken_plugins(fake_plugins, capsys):
    assert cli.main(["samplers"]) == 0
    out = capsys.readouterr().out
    assert "fake_import" in out and "BROKEN" in out and "pmc" in out


def test_unknown_name_lists_available():
    with pytest.raises(ValueError, match=r"unknown sampler 'nope'; available: .*pmc"):
        samplers.get("nope")
    with pytest.raises(ValueError, match="string"):
        samplers.get(3)


def test_local_registration():
    samplers.registry.register("local_good", Good)
    try:
        assert samplers.get("local_good") is Good
    finally:
        samplers.registry.unregister("local_good")
    with pytest.raises(TypeError):
        samplers.registry.register("local_bad", NeedsArgs)


@pytest.mark.parametrize("obj", [NeedsArgs, NoKeywords, not_a_class, object(), type("X", (), {})])
def test_validator_rejects(obj):
    with pytest.raises(TypeError):
        validate_sampler(obj)


def test_validator_accepts_var_keywords():
    class Kw:
        def run(self, target, **kw):
            return None

    validate_sampler(Kw)
    validate_sampler(Good)


def test_listing_does_not_import_heavy_dependencies():
    code = ("import sys, mrfpe.samplers as s; s.table(); heavy = ['emcee', 'nlopt', 'ot', "
            "'cv2', 'skimage', 'dask', 'matplotlib', 'sklearn', 'arviz']; "
            "print(','.join(m for m in heavy if m in sys.modules))")
    out = procs.python(code)
    assert out.stdout.strip() == "", f"listing imported {out.stdout.strip()}"


def test_broken_plugins_warn_once(fake_plugins):
    samplers.registry._warned.clear()
    with pytest.warns(RuntimeWarning) as rec:
        samplers.registry.entries(refresh=True)
    assert rec[0].filename == __file__  # points at the caller, not at mrfpe
    broken = {str(w.message).split("'")[1] for w in rec}
    assert {"fake_import", "fake_args", "fake_kw", "fake_func"} <= broken
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        samplers.registry.entries(refresh=True)  # once: no second warning
        samplers.available()


def test_get_and_sample_accept_a_class_or_an_instance():
    import mrfpe
    from mrfpe.samplers.pmc import PMC
    from mrfpe.testing import CorrelatedGaussian

    assert samplers.get(Good) is Good and samplers.registry.get(PMC) is PMC
    with pytest.raises(TypeError):
        samplers.get(NeedsArgs)
    t, cfg = CorrelatedGaussian(), {"n_samples": 50, "n_iterations": 2}
    by_name = mrfpe.sample("pmc", t, seed=1, **cfg)
    by_class = mrfpe.sample(PMC, t, seed=1, **cfg)
    by_instance = mrfpe.sample(PMC(**cfg), t, seed=1)
    for post in (by_class, by_instance):
        assert np.array_equal(post["theta"].values, by_name["theta"].values)
    with pytest.raises(TypeError, match="already constructed"):
        mrfpe.sample(PMC(), t, seed=1, n_samples=10)
    with pytest.raises(TypeError):
        mrfpe.sample(object(), t, seed=1)


def test_sample_names_the_nearest_setting():
    import mrfpe
    from mrfpe.testing import CorrelatedGaussian

    with pytest.raises(ValueError, match=r"sampler PMC has no parameter 'n_iter' \(did you mean "
                                         r"'n_iterations'\?\); parameters: n_samples, "):
        mrfpe.sample("pmc", CorrelatedGaussian(), seed=0, n_iter=5)


def _dist(root, name: str, module: str, body: str, entry: str) -> None:
    """A real installed distribution under ``root`` (dist-info + module) for entry points."""
    (root / f"{module}.py").write_text(body)
    info = root / f"{name}-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(f"[mrfpe.samplers]\n{entry}\n")


@pytest.fixture
def on_path(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(tmp_path))  # earlier on sys.path than mrfpe itself
    yield tmp_path
    monkeypatch.undo()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        samplers.registry.entries(refresh=True)


def test_a_plugin_cannot_take_over_a_builtin_name(on_path, capsys):
    _dist(on_path, "shadow-pmc", "shadow_pmc",
          "class Evil:\n    def run(self, target, *, seed=None, progress=False, "
          "callback=None):\n        return None\n", "pmc = shadow_pmc:Evil")
    with pytest.warns(RuntimeWarning, match=r"duplicate sampler name 'pmc': registered by "
                                            r"mrfpe .* and shadow-pmc 1.0"):
        samplers.registry.entries(refresh=True)
    assert samplers.get("pmc").__name__ == "PMC"
    assert "pmc" in samplers.available() and "pmc [shadow-pmc]" in samplers.broken()
    assert cli.main(["samplers"]) == 0
    out = capsys.readouterr().out
    pmc_row = next(line for line in out.splitlines() if line.startswith("pmc "))
    assert "BROKEN" not in pmc_row and "Population Monte Carlo" in pmc_row


def test_a_plugin_calling_sys_exit_on_import_is_listed_broken(on_path, capsys):
    _dist(on_path, "exits", "exits_on_import", "import sys\nsys.exit(3)\n",
          "exits = exits_on_import:S")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        samplers.registry.entries(refresh=True)
        assert cli.main(["samplers"]) == 0
    out = capsys.readouterr().out
    assert "exits" in out and "BROKEN: SystemExit: 3" in out and "pmc" in out

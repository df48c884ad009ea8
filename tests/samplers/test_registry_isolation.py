"""Hostile plugins: one that ends the process or hangs on import breaks no lookup and no
listing. Tests with such plugins run in a child process, so that a regression kills the
child, not the test runner."""

from __future__ import annotations

import json
import os
import signal
import sys
import textwrap
import time
import warnings
from typing import ClassVar

import pytest

import mrfpe._plugins as plugins
import mrfpe.samplers as samplers

from .. import _processes as procs
from .._dists import make_dist, on_sys_path, unique

SAMPLER = """
class S:
    '''A sampler plugin.'''

    def run(self, target, *, seed=None, progress=False, callback=None):
        return None
"""

HOSTILE = {
    "exits_mod": "import os\nos._exit(7)\n",
    "shadow_mod": "import os\nos._exit(8)\n",  # registers the built-in name 'pmc'
    "killed_mod": "import os, signal\nos.kill(os.getpid(), signal.SIGKILL)\n",
    "sysexit_mod": "import sys\nsys.exit(3)\n",
    "hangs_mod": ("import os, time\nopen(os.environ['HANG_PID'], 'w').write(str(os.getpid()))"
                  "\ntime.sleep(600)\n"),
    "good_mod": SAMPLER,
    # a plugin printing on import must not confuse the probe's report
    "noisy_mod": "print('[\"done\", 0, \"not me\"]')\nprint('{oops')\n" + SAMPLER,
}


@pytest.fixture
def site(tmp_path, monkeypatch):
    yield from on_sys_path(tmp_path, monkeypatch)


@pytest.fixture
def hostile(tmp_path):
    root = tmp_path / "site"
    root.mkdir()
    names = {"exits": "exits_mod:S", "pmc": "shadow_mod:S", "killed": "killed_mod:S",
             "sysexit": "sysexit_mod:S", "hangs": "hangs_mod:S", "good": "good_mod:S",
             "noisy": "noisy_mod:S"}
    make_dist(root, "hostile", HOSTILE, {"mrfpe.samplers": names,
                                         "mrfpe.distances": {"exits_d": "exits_mod:D"},
                                         "mrfpe.models": {"exits_m": "exits_mod:f"}})
    return {**os.environ, "PYTHONPATH": str(root), "HANG_PID": str(tmp_path / "hang.pid")}


def _python(code: str, env: dict[str, str], **kw):
    return procs.python(textwrap.dedent(code), env=env, check=False, **kw)


def test_a_lookup_imports_only_the_name_asked(hostile):
    done = _python("""
        import sys
        import mrfpe, mrfpe.samplers as s, mrfpe.distances as d, mrfpe.models as m
        from mrfpe.testing import CorrelatedGaussian

        print(s.get("pmc").__name__, s.get("good").__name__, d.get("kl").__name__,
              m.get("potts").name)
        post = mrfpe.sample("pmc", CorrelatedGaussian(), seed=0, n_samples=50, n_iterations=2)
        print(post.sizes["sample"], [k for k in sys.modules if k.endswith("_mod")])
    """, hostile)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == ["PMC S KL potts", "50 ['good_mod']"]
    # the plugin taking 'pmc' is named from its metadata, never imported
    assert "duplicate sampler name 'pmc': registered by mrfpe" in done.stderr
    assert "hostile 1.0 (shadow_mod:S); mrfpe's is kept" in done.stderr


@pytest.mark.parametrize("fork", [True, False], ids=["forked", "spawned"])
def test_listing_survives_plugins_that_exit_hang_or_are_killed(hostile, tmp_path, fork):
    done = _python(f"""
        import json, time, warnings
        import mrfpe._plugins as p
        p.PROBE_TIMEOUT = 3.0
        p._can_fork = lambda: {fork}
        import mrfpe.samplers as s
        from mrfpe.cli import main

        warnings.simplefilter("ignore", RuntimeWarning)
        start = time.monotonic()
        rc = main(["samplers"])
        print(json.dumps({{"rc": rc, "s": time.monotonic() - start, "errors": s.broken(),
                           "names": s.available()}}))
    """, hostile, timeout=120)
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout.splitlines()[-1])
    assert report["rc"] == 0
    errors = report["errors"]
    assert errors["exits"] == "loading it ended the process (exit status 7)"
    assert errors["killed"] == "loading it ended the process (killed by signal 9, Killed)"
    assert errors["hangs"] == "loading it did not finish within 3 s (does it hang?)"
    assert errors["sysexit"] == "SystemExit: 3"
    assert errors["pmc [hostile]"].startswith("duplicate sampler name 'pmc'")
    assert {"good", "noisy", "pmc", "sir"} <= set(report["names"])
    assert report["s"] < 30  # one 3 s timeout, a few process starts
    listing = done.stdout
    assert "BROKEN: loading it ended the process (exit status 7)" in listing
    pid = int((tmp_path / "hang.pid").read_text())
    with pytest.raises(ProcessLookupError):  # the hanging probe was killed and reaped
        os.kill(pid, 0)


@pytest.mark.parametrize("command", ["distances", "models"])
def test_every_listing_command_survives(hostile, command):
    done = procs.run([sys.executable, "-m", "mrfpe", command], env=hostile, check=False,
                     timeout=120)
    assert done.returncode == 0, done.stderr
    row = next(line for line in done.stdout.splitlines() if line.startswith("exits_"))
    assert "BROKEN: loading it ended the process (exit status 7)" in row


@pytest.mark.parametrize("fork", [True, False], ids=["forked", "spawned"])
def test_the_probe_restores_sigint_even_when_the_parent_ignores_it(tmp_path, fork):
    """A probe inheriting an ignored SIGINT (a shell's background job) would shrug off
    Ctrl-C; it resets SIGINT to its default before importing anything."""
    root = tmp_path / "site"
    root.mkdir()
    log_handler = ("import os, signal\n"
                   "with open(os.environ['SIGNAL_LOG'], 'a') as log:\n"
                   "    log.write(str(int(signal.getsignal(signal.SIGINT))) + '\\n')\n")
    make_dist(root, "sigcheck", {"sigcheck_mod": log_handler + SAMPLER},
              {"mrfpe.samplers": {"sigcheck": "sigcheck_mod:S"}})
    log = tmp_path / "signal.log"
    done = _python(f"""
        import signal
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        import mrfpe._plugins as p
        p._can_fork = lambda: {fork}
        import mrfpe.samplers as s
        print("sigcheck" in s.available())
    """, {**os.environ, "PYTHONPATH": str(root), "SIGNAL_LOG": str(log)})
    assert done.stdout.strip() == "True", done.stderr
    # the probe first, then the import in-process (which keeps the parent's handler)
    assert log.read_text().splitlines() == [str(int(h)) for h in (signal.SIG_DFL,
                                                                   signal.SIG_IGN)]


def test_ctrl_c_during_a_hanging_probe_ends_the_listing_and_the_probe(hostile, tmp_path):
    pid_file = tmp_path / "hang.pid"
    with procs.Child([sys.executable, "-m", "mrfpe", "samplers"], env=hostile) as child:
        deadline = time.monotonic() + 120
        while not (pid_file.exists() and pid_file.read_text()):
            assert time.monotonic() < deadline, f"the probe never reached the hanging plugin: " \
                                                f"{child.stderr}"
            assert child.returncode is None, child.stderr
            time.sleep(0.05)
        child.send_signal(signal.SIGINT)  # to the listing only, as a kill -INT would
        assert child.finish(timeout=30) == 130
        assert "mrfpe samplers: interrupted" in child.stderr
    with pytest.raises(ProcessLookupError):
        os.kill(int(pid_file.read_text()), 0)


class _Recording(plugins._Probe):
    started: ClassVar[list[list[str]]] = []

    def __init__(self, values, check):
        type(self).started.append(list(values))
        super().__init__(values, check)


def test_a_healthy_listing_starts_one_probe_and_probes_no_built_in(site, request,
                                                                    monkeypatch):
    mods = [unique(request, f"healthy{i}") for i in range(3)]
    make_dist(site, "healthy", {m: SAMPLER for m in mods} | {mods[0]: HOSTILE["noisy_mod"]},
              {"mrfpe.samplers": {f"h{i}": f"{m}:S" for i, m in enumerate(mods)}})
    monkeypatch.setattr(_Recording, "started", [])
    monkeypatch.setattr(plugins, "_Probe", _Recording)
    monkeypatch.setattr(plugins, "_can_fork", lambda: False)  # as in a runner with threads
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        entries = samplers.registry.entries(refresh=True)
    assert {"h0", "h1", "h2"} <= {k for k, v in entries.items() if v.ok}
    assert len(_Recording.started) == 1  # one child for every third-party plugin
    probed = _Recording.started[0]
    assert {f"{m}:S" for m in mods} <= set(probed)
    assert not [v for v in probed if v.startswith("mrfpe.")]
    samplers.registry.entries(refresh=True)  # their modules are imported now: no probe
    assert len(_Recording.started) == 1


def test_without_a_probe_process_plugins_load_in_process(site, request, monkeypatch):
    mod = unique(request, "unprobed")
    make_dist(site, "unprobed", {mod: SAMPLER}, {"mrfpe.samplers": {"unprobed": f"{mod}:S"}})

    def no_process(*args, **kwargs):
        raise OSError("no more processes")

    monkeypatch.setattr(plugins.subprocess, "Popen", no_process)
    monkeypatch.setattr(plugins, "_can_fork", lambda: False)
    assert samplers.registry.entries(refresh=True)["unprobed"].ok


@pytest.mark.parametrize("command", ["samplers", "distances", "models"])
def test_a_listing_forks_one_probe_once_the_built_ins_are_loaded(tmp_path, command):
    """In a process with one thread (the command line) the probe is a fork made after the
    built-ins load: it shares what they imported, so a healthy listing stays cheap."""
    root = tmp_path / "site"
    root.mkdir()
    make_dist(root, "healthy", {"healthy_mod": SAMPLER + textwrap.dedent("""
        import mrfpe.models

        class D:
            kind = "distance"
            symmetric = True
            params = {}

            def __call__(self, a, b):
                return 0.0

        def model():
            return mrfpe.models.potts()
    """)}, {"mrfpe.samplers": {"h": "healthy_mod:S"}, "mrfpe.distances": {"h": "healthy_mod:D"},
           "mrfpe.models": {"h": "healthy_mod:model"}})
    builtin = {"samplers": "mrfpe.samplers.pmc", "distances": "mrfpe.distances.gaussian",
               "models": "mrfpe.models.library"}[command]
    done = _python(f"""
        import json, sys
        import mrfpe._plugins as p

        started, start = [], p._Probe._start

        def record(self):
            started.append((self.values, self.check, {builtin!r} in sys.modules,
                            p._can_fork()))
            start(self)

        p._Probe._start = record
        from mrfpe.cli import main

        assert main(["{command}"]) == 0
        print(json.dumps(started), file=sys.stderr)
    """, {**os.environ, "PYTHONPATH": str(root)})
    assert done.returncode == 0, done.stderr
    started = json.loads(done.stderr.strip().splitlines()[-1])
    assert len(started) == 1, started
    values, check, builtins_loaded, forked = started[0]
    assert "healthy_mod:" + {"samplers": "S", "distances": "D", "models": "model"}[command] \
        in values
    assert builtins_loaded and forked
    assert check == ("mrfpe.models.registry:check_model_factory" if command == "models"
                     else None)
    row = next(line for line in done.stdout.splitlines() if line.startswith("h "))
    assert "BROKEN" not in row

"""The suite cannot hang on a child process, however it is started.

Children go through ``tests/_processes.py``: SIGINT at its default in the child even
when the suite runs as a background job (which ignores SIGINT), and every wait with a
deadline. A scan of the test sources keeps it that way.
"""

from __future__ import annotations

import ast
import sys
import textwrap
import time
from pathlib import Path

import pytest

from . import _processes as procs

ROOT = Path(__file__).resolve().parents[1]
HELPER = Path(procs.__file__).resolve()

# Whatever starts a process; a test module reaching for one of these bypasses the helper.
_MODULES = {"subprocess", "multiprocessing", "pty", "pexpect"}
_NAMES = {"ProcessPoolExecutor", "create_subprocess_exec", "create_subprocess_shell"}
_OS_PREFIXES = ("system", "popen", "fork", "spawn", "posix_spawn", "exec")


def _os_call(name: str) -> bool:
    return name.startswith(_OS_PREFIXES)


def process_starts(source: str) -> list[tuple[int, str]]:
    """(line, what) for each way ``source`` could start a process without the helper."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [(node.lineno, f"import {a.name}") for a in node.names
                      if a.name.split(".")[0] in _MODULES]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            top = node.module.split(".")[0]
            names = [a.name for a in node.names]
            if top in _MODULES or any(n in _NAMES or (top == "os" and _os_call(n))
                                      for n in names):
                found.append((node.lineno, f"from {node.module} import {', '.join(names)}"))
        elif isinstance(node, ast.Attribute):
            if node.attr in _NAMES or (isinstance(node.value, ast.Name)
                                       and node.value.id == "os" and _os_call(node.attr)):
                found.append((node.lineno, ast.unparse(node)))
        elif (isinstance(node, ast.Call) and node.args
              and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)
              and node.args[0].value.split(".")[0] in _MODULES
              and ast.unparse(node.func).split(".")[-1] in ("__import__", "import_module")):
            found.append((node.lineno, ast.unparse(node)))
    return sorted(found)


def _test_sources() -> list[Path]:
    files = [*ROOT.glob("tests/**/*.py"), *ROOT.glob("plugins/*/tests/**/*.py")]
    return sorted(p for p in files if p.resolve() != HELPER)


def test_no_test_starts_a_process_without_the_helper():
    bad = [f"{path.relative_to(ROOT)}:{line}: {what}"
           for path in _test_sources() for line, what in process_starts(path.read_text())]
    assert not bad, ("start child processes with tests/_processes.py (run, python, Child), "
                     "which restores SIGINT and bounds every wait:\n" + "\n".join(bad))


def test_the_scan_finds_each_way_in():
    source = textwrap.dedent("""
        import os, json
        import multiprocessing.pool
        from subprocess import run
        from concurrent.futures import ProcessPoolExecutor
        def f():
            import subprocess as sp
            os.system("true")
            os.execvp("x", ["x"])
            os.posix_spawnp("x", ["x"], {})
            asyncio.create_subprocess_exec("x")
            importlib.import_module("subprocess")
            __import__("pty")
            json.dumps(os.path.join("a", "b"))  # not a process
        """)
    assert [line for line, _ in process_starts(source)] == [3, 4, 5, 7, 8, 9, 10, 11, 12, 13]
    assert process_starts("from . import _processes as procs\nprocs.run(['x'])\n") == []


# The child's view of SIGINT: its Python handler is the usual one, and it is not blocked.
_SHOW_SIGINT = ("import signal; print(signal.getsignal(signal.SIGINT) is "
                "signal.default_int_handler, signal.SIGINT in "
                "signal.pthread_sigmask(signal.SIG_BLOCK, []))")


def test_a_child_gets_sigint_back_where_the_suite_ignores_it():
    """As in a background job: SIGINT ignored (and, for good measure, blocked) here."""
    code = f"""
        import signal, subprocess, sys
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.pthread_sigmask(signal.SIG_BLOCK, {{signal.SIGINT}})
        sys.path.insert(0, {str(ROOT)!r})
        from tests import _processes as procs
        plain = subprocess.run([sys.executable, "-c", {_SHOW_SIGINT!r}], capture_output=True,
                               text=True, timeout=60)
        print(plain.stdout.strip())
        print(procs.python({_SHOW_SIGINT!r}, timeout=60).stdout.strip())
        """
    plain, helped = procs.python(textwrap.dedent(code), timeout=120).stdout.splitlines()
    assert plain == "False True"  # what a plain subprocess inherits: the hang
    assert helped == "True False"


def test_a_child_keeps_its_pid_argv_and_environment(tmp_path):
    with procs.Child([sys.executable, "-c", "import os, sys; print(os.getpid(), sys.argv[1:], "
                      "os.environ['PROBE'], os.getcwd())", "a b", ""], cwd=tmp_path,
                     env={"PROBE": "x y"}) as child:
        assert child.finish(timeout=60) == 0, child.stderr
    assert child.stdout.split("\n")[0] == f"{child.pid} ['a b', ''] x y {tmp_path}"


def test_a_hung_run_is_killed_and_fails_the_test_naming_it():
    t0 = time.monotonic()
    with pytest.raises(pytest.fail.Exception) as info:
        procs.python("import time; print('started', flush=True); time.sleep(600)", timeout=2)
    assert time.monotonic() - t0 < 30
    message = str(info.value)
    assert "killed after 2 s without finishing" in message and "time.sleep(600)" in message
    assert "started" in message  # the output so far


def test_a_failed_run_shows_its_stderr():
    with pytest.raises(pytest.fail.Exception, match=r"exit status 3: .*\n--- stderr .*\nwhy"):
        procs.python("import sys; print('why', file=sys.stderr); sys.exit(3)")
    assert procs.python("import sys; sys.exit(3)", check=False).returncode == 3


def test_waiting_for_output_that_never_comes_is_bounded():
    with procs.Child([sys.executable, "-c", "import time; print('a', flush=True); "
                      "time.sleep(600)"]) as child:
        assert "a" in child.wait_for("stdout", lambda text: "a" in text.split(), "'a'")
        t0 = time.monotonic()
        with pytest.raises(pytest.fail.Exception, match=r"no 'b' within 1 s"):
            child.wait_for("stdout", lambda text: "b" in text.split(), "'b'", timeout=1)
        assert time.monotonic() - t0 < 30
        assert child.returncode is not None  # killed, not left running


def test_output_that_ends_first_fails_at_once():
    with procs.Child([sys.executable, "-c", "print('done')"]) as child:
        with pytest.raises(pytest.fail.Exception, match="closed its stderr before any error"):
            child.wait_for("stderr", bool, "any error")


def test_finishing_is_bounded():
    with procs.Child([sys.executable, "-c", "import time; time.sleep(600)"]) as child:
        with pytest.raises(pytest.fail.Exception, match="still running after 1 s"):
            child.finish(timeout=1)
        assert child.returncode is not None

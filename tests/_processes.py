"""Child processes for the tests: SIGINT as in a terminal, and no wait without a deadline.

Tests start processes only through :func:`run`, :func:`python` or :class:`Child`
(``tests/test_processes.py`` scans the test sources for any other way).

SIGINT. A shell without job control (a script, ``bash -c``, CI) starts ``cmd &`` with
SIGINT ignored, and an ignored signal survives fork and exec: the child shrugs off the
SIGINT a test sends, and a Python child installs no KeyboardInterrupt handler. So each
child starts as a short Python prelude that sets SIGINT to its default, unblocks it
and execs the real command (same pid, argv, environment). Not ``preexec_fn``: the
subprocess documentation calls it unsafe with threads (xdist and numba run threads
here), and a child deadlocked between fork and exec is the very hang to avoid. Not a
prelude prepended to ``-c`` code: that misses ``-m`` and non-Python commands.
``restore_signals`` covers only SIGPIPE and the file-size signals.

Deadlines. ``read()`` or ``readline()`` on a pipe waits while the child keeps it open,
so :class:`Child` drains both pipes on threads and every wait is a condition wait with
a deadline. Past it the child is killed and the test fails, naming the command and
showing the end of its output.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import pytest

# Run as ``python -I -S -c PRELUDE cmd args...``: -I -S keep the extra startup short
# and independent of the environment, which the exec'd command still receives whole.
PRELUDE = ("import os, signal, sys; "
           "signal.signal(signal.SIGINT, signal.SIG_DFL); "
           "signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT}); "
           "os.execvp(sys.argv[1], sys.argv[1:])")

#: Seconds a child may take unless the test says otherwise: a guard against a hang,
#: not a performance bound (a cold numba cache compiles for a while).
TIMEOUT = 300.0

_TAIL = 3000  # characters of output shown when a child fails


def sigint_default(argv: Sequence[str | os.PathLike]) -> list[str]:
    """``argv`` behind the prelude that restores SIGINT's default before the exec."""
    return [sys.executable, "-I", "-S", "-c", PRELUDE, *(os.fspath(a) for a in argv)]


def _show(argv: Sequence[str], stdout: str, stderr: str) -> str:
    shown = " ".join(argv)
    for name, text in (("stdout", stdout), ("stderr", stderr)):
        if text.strip():
            shown += f"\n--- {name} (end) ---\n{text[-_TAIL:]}"
    return shown


def _text(data: bytes | str | None) -> str:
    if isinstance(data, bytes):
        return data.decode(errors="replace")
    return data or ""


def run(argv: Sequence[str | os.PathLike], *, timeout: float = TIMEOUT, check: bool = True,
        env: Mapping[str, str] | None = None, cwd: str | Path | None = None,
        ) -> subprocess.CompletedProcess[str]:
    """Run ``argv`` to completion with stdin closed and stdout, stderr captured as text.

    Past ``timeout`` seconds the child is killed and the test fails; with ``check`` a
    non-zero exit fails it too, showing stderr (CalledProcessError would not).
    """
    argv = [os.fspath(a) for a in argv]
    try:
        # run() kills the child on its timeout and reaps it without reading the pipes
        done = subprocess.run(sigint_default(argv), stdin=subprocess.DEVNULL,
                              capture_output=True, text=True, timeout=timeout,
                              env=None if env is None else dict(env), cwd=cwd)
    except subprocess.TimeoutExpired as exc:
        pytest.fail(f"killed after {timeout:g} s without finishing: "
                    f"{_show(argv, _text(exc.stdout), _text(exc.stderr))}", pytrace=False)
    if check and done.returncode:
        pytest.fail(f"exit status {done.returncode}: {_show(argv, done.stdout, done.stderr)}",
                    pytrace=False)
    return done


def python(code: str, **kw) -> subprocess.CompletedProcess[str]:
    """:func:`run` of ``python -c code`` in this interpreter."""
    return run([sys.executable, "-c", code], **kw)


class Child:
    """A running child whose stdout and stderr are read on threads, so no wait is unbounded.

    Use it as a context manager: leaving the block kills the child if it still runs.
    """

    def __init__(self, argv: Sequence[str | os.PathLike], *,
                 env: Mapping[str, str] | None = None, cwd: str | Path | None = None):
        self.argv = [os.fspath(a) for a in argv]
        self._proc = subprocess.Popen(sigint_default(self.argv), stdin=subprocess.DEVNULL,
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                      env=None if env is None else dict(env), cwd=cwd)
        self._data = {"stdout": bytearray(), "stderr": bytearray()}
        self._eof = {"stdout": False, "stderr": False}
        self._changed = threading.Condition()
        self._readers = [threading.Thread(target=self._drain, args=(name, pipe), daemon=True)
                         for name, pipe in (("stdout", self._proc.stdout),
                                            ("stderr", self._proc.stderr))]
        for reader in self._readers:
            reader.start()

    def _drain(self, name: str, pipe) -> None:
        while chunk := pipe.read1(1 << 16):
            with self._changed:
                self._data[name] += chunk
                self._changed.notify_all()
        with self._changed:
            self._eof[name] = True
            self._changed.notify_all()

    @property
    def pid(self) -> int:
        return self._proc.pid

    @property
    def returncode(self) -> int | None:
        return self._proc.poll()

    @property
    def stdout(self) -> str:
        """What the child has written to stdout so far."""
        with self._changed:
            return self._data["stdout"].decode(errors="replace")

    @property
    def stderr(self) -> str:
        """What the child has written to stderr so far."""
        with self._changed:
            return self._data["stderr"].decode(errors="replace")

    def send_signal(self, sig: int) -> None:
        self._proc.send_signal(sig)

    def wait_for(self, stream: str, predicate: Callable[[str], object], what: str, *,
                 timeout: float = TIMEOUT) -> str:
        """Wait until ``predicate(text written to stream so far)``; return that text.

        Fails the test, the child killed, if the stream closes first or ``timeout``
        seconds pass; ``what`` names the awaited output in that message.
        """
        deadline = time.monotonic() + timeout
        with self._changed:
            while True:
                text = self._data[stream].decode(errors="replace")
                if predicate(text):
                    return text
                if self._eof[stream]:
                    break
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                self._changed.wait(left)
        self._fail(f"closed its {stream} before {what}" if self._eof[stream]
                   else f"no {what} within {timeout:g} s")

    def finish(self, *, timeout: float = TIMEOUT) -> int:
        """Wait for the exit and for both streams to close; return the exit status."""
        deadline = time.monotonic() + timeout
        try:
            self._proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self._fail(f"still running after {timeout:g} s")
        with self._changed:
            # a grandchild may hold a pipe open after the child exits
            ended = self._changed.wait_for(lambda: all(self._eof.values()),
                                           max(0.0, deadline - time.monotonic()))
        if not ended:
            self._fail(f"exited, but its output did not end within {timeout:g} s")
        return self._proc.returncode

    def kill(self) -> None:
        """Kill the child if it still runs, and reap it."""
        if self._proc.poll() is None:
            self._proc.kill()
        try:
            self._proc.wait(timeout=30)  # SIGKILL: only an uninterruptible sleep delays it
        except subprocess.TimeoutExpired:
            pass
        for reader in self._readers:
            reader.join(timeout=5)
        if not any(reader.is_alive() for reader in self._readers):
            # closing a pipe under a blocked reader would be a race: only once they are done
            self._proc.stdout.close()
            self._proc.stderr.close()

    def _fail(self, why: str):
        self.kill()
        pytest.fail(f"{why}: {_show(self.argv, self.stdout, self.stderr)}", pytrace=False)

    def __enter__(self) -> Child:
        return self

    def __exit__(self, *exc) -> None:
        self.kill()

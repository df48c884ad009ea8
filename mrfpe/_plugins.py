"""Entry-point registries shared by samplers, distances, models, targets and studies.

As xarray's backends: every extension, built-in or third-party, is a class under an entry-point
group. Failures are *broken* entries with the reason, never raised; a plugin taking a built-in's
name is listed broken with a warning naming both distributions. A lookup imports only the entry
point kept under its name (decided on metadata). A listing imports all, each third-party one
first in a child process (a fork once the built-ins are loaded, else a new interpreter), within
:data:`PROBE_TIMEOUT` s: one that ends that process or hangs is broken, never imported here.
"""

from __future__ import annotations

import dataclasses
import importlib.metadata as md
import inspect
import json
import os
import queue
import signal
import subprocess
import sys
import threading
import time
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from typing import IO, Any

from mrfpe._caller import stacklevel_outside_mrfpe
from mrfpe._terminal import WIDTH, plain, shorten, table

__all__ = ["PROBE_TIMEOUT", "PluginError", "PluginInfo", "Registry", "is_builtin", "one_line",
           "short_repr"]

#: Seconds a third-party plugin may take to load in a listing's probe process (a hang guard).
PROBE_TIMEOUT = 60.0
_PROBE_CHILD = "MRFPE_PLUGIN_PROBE_CHILD"  # set there: a plugin listing plugins won't probe

# The probe: SIGINT at its default (Ctrl-C ends it even under a shell ignoring it); the report
# on a copy of stdout, plugins' prints discarded; "start" first, so that a death names it.
_PROBE_CODE = r"""
import importlib.metadata as md, json, os, signal, sys
signal.signal(signal.SIGINT, signal.SIG_DFL)
hasattr(signal, "pthread_sigmask") and signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
report, _ = os.fdopen(os.dup(1), "w"), os.dup2(2, 1)
request = globals().get("REQUEST") or json.loads(sys.argv[1])  # forked: given
sys.path[:] = request["path"]
load = lambda value: md.EntryPoint("", value, "").load()
check = request["check"] and load(request["check"])  # failing: the parent loads in-process
for i, value in enumerate(request["values"]):
    print(json.dumps(["start", i]), file=report, flush=True)
    try:
        obj = load(value)
        error = check(obj) if check else None
    except BaseException as exc:
        error = f"{type(exc).__name__}: {exc}"
    print(json.dumps(["done", i, error]), file=report, flush=True)
"""


class PluginError(RuntimeError):
    """A third-party plugin failed while mrfpe ran it; the message names the plugin."""


@dataclasses.dataclass(frozen=True)
class PluginInfo:
    """One registered plugin, working or broken."""

    name: str
    target: str  # "module:attr" of the entry point
    package: str
    version: str
    description: str
    obj: Any = None
    error: str | None = None

    @property
    def ok(self) -> bool:
        return self.error is None


def is_builtin(info: PluginInfo) -> bool:
    """Whether ``info`` is one of mrfpe's own entry points (its errors are mrfpe's)."""
    return info.package == "mrfpe" and info.target.startswith("mrfpe.")


def one_line(text: str, limit: int = 300) -> str:
    """``text`` with whitespace runs (newlines included) made one space, cut to ``limit``."""
    return shorten(" ".join(str(text).split()), limit)


def short_repr(obj: Any, limit: int = 60) -> str:
    """A one-line ``repr`` of ``obj`` for messages (its type name if ``repr`` fails)."""
    try:
        return one_line(repr(obj), limit)
    except Exception:  # a plugin's object may fail even at this
        return f"<{type(obj).__name__}>"


def first_doc_line(obj: Any) -> str:
    """The first non-empty line of ``obj``'s docstring ('' if none)."""
    return (inspect.getdoc(obj) or "").strip().partition("\n")[0].strip()


def check_no_arg_constructible(obj: Any, name: str) -> None:
    """Raise TypeError unless every constructor parameter of class ``obj`` has a default."""
    try:
        init_sig = inspect.signature(obj.__init__)
    except (TypeError, ValueError):  # pragma: no cover - builtins without signatures
        return
    required = [p.name for p in list(init_sig.parameters.values())[1:]
                if p.default is p.empty and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]
    if required:
        raise TypeError(f"{name}() must be constructible with no arguments; "
                        f"parameters without defaults: {', '.join(required)}")


def _stub(ep: md.EntryPoint, description: str = "", obj: Any = None,
          error: str | None = None) -> PluginInfo:
    """A PluginInfo from the entry point's metadata alone (nothing imported)."""
    dist = getattr(ep, "dist", None)
    meta = ("?", "?") if dist is None else (dist.metadata["Name"] or "?", dist.version)
    return PluginInfo(ep.name, ep.value, *meta, description, obj, error)


def _drain(stream: IO[str], lines: queue.Queue) -> None:
    with stream:
        for line in stream:
            lines.put(line)
    lines.put(None)  # end of file: the process closed its report


class _Probe:
    """Import entry-point targets in a child process, each within :data:`PROBE_TIMEOUT` (one it
    dies or hangs on is broken; a new child takes the rest): :meth:`results` ``{target: error
    or None}``, without those that could not be probed (no child)."""

    def __init__(self, values: list[str], check: str | None):
        self.values, self.check, self.errors = values, check, {}
        self._next = 0  # first value without a result
        self._start()

    def _start(self) -> None:
        self._lines: queue.Queue = queue.Queue()
        self._proc: subprocess.Popen | _Forked | None = None
        self._base = self._next
        request = {"path": sys.path, "check": self.check, "values": self.values[self._next:]}
        try:
            if _can_fork():
                report = self._fork(request)
            else:  # a new interpreter, given the request as its argument
                self._proc = subprocess.Popen(
                    [sys.executable, "-c", _PROBE_CODE, json.dumps(request, default=str)],
                    stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                    stderr=subprocess.DEVNULL, text=True, env={**os.environ, _PROBE_CHILD: "1"})
                report = self._proc.stdout
        except OSError:  # no process to be had: the caller imports in-process
            return
        threading.Thread(target=_drain, args=(report, self._lines), daemon=True).start()

    def _fork(self, request: dict[str, Any]) -> IO[str]:
        """A copy of this process runs the probe: what it imported, the plugins need not."""
        read, write = os.pipe()
        try:
            with warnings.catch_warnings():  # Python 3.12+ warns of native (BLAS) threads
                warnings.simplefilter("ignore", DeprecationWarning)
                pid = os.fork()
        except OSError:
            os.close(read), os.close(write)
            raise
        if pid == 0:  # the child: it never returns into the caller's code
            try:
                null = os.open(os.devnull, os.O_RDWR)
                os.dup2(null, 0), os.dup2(write, 1), os.dup2(null, 2)
                os.environ[_PROBE_CHILD] = "1"
                exec(_PROBE_CODE, {"REQUEST": request})
            finally:
                os._exit(0)
        os.close(write)
        self._proc = _Forked(pid)
        return os.fdopen(read)

    def results(self) -> dict[str, str | None]:
        try:
            while self._proc is not None and self._next < len(self.values):
                self._step()
        finally:
            self._stop()
        return self.errors

    def _step(self) -> None:
        current = None  # index of the value the child is importing
        while True:
            try:
                msg = self._lines.get(timeout=PROBE_TIMEOUT)
            except queue.Empty:
                msg = ""  # nothing within PROBE_TIMEOUT
            if not msg:  # that, or None: the end of the report
                break
            try:
                kind, i, *error = json.loads(msg)
                current, value = self._base + i, self.values[self._base + i]
            except (ValueError, TypeError, IndexError):  # not the report (a plugin's fork?)
                continue
            if kind == "done":
                self.errors[value] = one_line(error[0]) if isinstance(error[0], str) else None
                self._next, current = current + 1, None
                if self._next == len(self.values):
                    return
        status = self._stop(kill=msg == "")
        self._proc = None
        if current is None:  # it never began the next import: leave the rest unprobed
            return
        how = (f"exit status {status}" if status is None or status >= 0 else
               f"killed by signal {-status}, {signal.strsignal(-status)}")
        self.errors[self.values[current]] = (
            f"loading it did not finish within {PROBE_TIMEOUT:g} s (does it hang?)"
            if msg == "" else f"loading it ended the process ({how})")
        self._next = current + 1
        if self._next < len(self.values):
            self._start()

    def _stop(self, kill: bool = True) -> int | None:
        """Reap the child, killed first if ``kill`` or if it outlives 5 s; its exit status."""
        for force in (kill, True) if self._proc is not None else ():
            if force:
                self._proc.kill()
            with suppress(subprocess.TimeoutExpired):
                return self._proc.wait(timeout=5)
        return None


def _can_fork() -> bool:
    # a fork copies one thread: only if no other may hold a lock (not macOS: its frameworks)
    return sys.platform == "linux" and threading.active_count() == 1


class _Forked:
    """A forked probe's handle: what :class:`_Probe` uses of ``subprocess.Popen``."""

    def __init__(self, pid: int):
        self.pid, self.returncode = pid, None

    def kill(self) -> None:
        if self.returncode is None:  # not reaped yet: the pid is still its own
            os.kill(self.pid, signal.SIGKILL)

    def wait(self, timeout: float) -> int:
        deadline = time.monotonic() + timeout
        while self.returncode is None:
            pid, status = os.waitpid(self.pid, os.WNOHANG)
            if pid:
                self.returncode = os.waitstatus_to_exitcode(status)
            elif time.monotonic() > deadline:
                raise subprocess.TimeoutExpired("probe", timeout)
            time.sleep(0.005)
        return self.returncode


class Registry:
    """Discover, validate and look up the plugins of one entry-point group.

    Parameters
    ----------
    group, kind : entry-point group (``"mrfpe.samplers"``), name in messages (``"sampler"``).
    validate : raises (``TypeError``) unless a loaded object implements the interface.
    check_loaded : deeper check of what an entry point loads (not :meth:`register`'s objects,
        the caller's own), e.g. that a model factory builds a model; run in the probe too.
    """

    def __init__(self, group: str, kind: str, validate: Callable[[Any], None],
                 check_loaded: Callable[[Any], None] | None = None):
        self.group, self.kind = group, kind
        self._validate, self._check_loaded = validate, check_loaded
        name = getattr(check_loaded, "__qualname__", "<")  # the probe imports it by name
        self._check_path = None if "<" in name else f"{check_loaded.__module__}:{name}"
        self._entries: dict[str, PluginInfo] | None = None  # the whole listing, once made
        self._eps: dict[str, list[md.EntryPoint]] | None = None  # by name, from metadata
        self._loaded: dict[tuple[str, str], PluginInfo] = {}  # by (name, target)
        self._local: dict[str, PluginInfo] = {}
        self._warned: set[tuple[str, str]] = set()  # (name, error) already warned about

    def _load(self, ep: md.EntryPoint) -> PluginInfo:
        """Import and check one entry point in this process."""
        try:
            obj = ep.load()
            self._validate(obj)
            if self._check_loaded is not None:
                self._check_loaded(obj)
        except (Exception, SystemExit) as exc:  # nor may a plugin's sys.exit end the process
            return _stub(ep, error=one_line(f"{type(exc).__name__}: {exc}"))
        return _stub(ep, first_doc_line(obj), obj)

    def _by_name(self) -> dict[str, list[md.EntryPoint]]:
        """The group's entry points by name, sorted, each (name, target) once: metadata only."""
        if self._eps is None:
            eps: dict[str, list[md.EntryPoint]] = {}
            for ep in sorted(md.entry_points(group=self.group), key=lambda e: e.name):
                same = eps.setdefault(ep.name, [])
                if all(e.value != ep.value for e in same):  # not one dist seen twice on sys.path
                    same.append(ep)
            self._eps = eps
        return self._eps

    def _claims(self, name: str) -> tuple[md.EntryPoint, dict[str, PluginInfo]]:
        """The entry point kept under ``name`` and the broken entries of the others: the
        first registration, or a built-in (never taken over). Nothing is imported."""
        eps = self._by_name()[name]
        kept = next((ep for ep in eps if is_builtin(_stub(ep))), eps[0])
        k, dups = _stub(kept), {}
        for d in (_stub(ep) for ep in eps if ep is not kept):
            dups[f"{name} [{d.package}]"] = dataclasses.replace(d, error=(
                f"duplicate {self.kind} name {name!r}: registered by {k.package} {k.version} "
                f"({k.target}) and {d.package} {d.version} ({d.target}); {k.package}'s is kept"))
        return kept, dups

    def _load_all(self, eps: list[md.EntryPoint]) -> None:
        """Load ``eps`` not loaded yet; third-party ones are first imported by a probe process."""
        todo = [ep for ep in eps if (ep.name, ep.value) not in self._loaded]
        # third-party modules not imported yet (nothing would run), unless in a probe already
        probed = [ep for ep in todo if not is_builtin(_stub(ep)) and ep.module not in
                  sys.modules and not os.environ.get(_PROBE_CHILD)]
        values, check = [ep.value for ep in probed], self._check_path
        # a spawned probe runs while the built-ins load; a forked one after, sharing them
        probe = values and not _can_fork() and _Probe(values, check)
        for ep in todo:
            if ep not in probed:
                self._loaded[ep.name, ep.value] = self._load(ep)
        probe = probe or (values and _Probe(values, check))
        errors = probe.results() if probe else {}
        for ep in probed:
            error = errors.get(ep.value)
            self._loaded[ep.name, ep.value] = _stub(ep, error=error) if error else self._load(ep)

    def entries(self, refresh: bool = False) -> dict[str, PluginInfo]:
        """Every plugin of the group, broken ones included, by name (imports them all)."""
        if self._entries is None or refresh:
            if refresh:
                self._eps, self._loaded = None, {}
            claims = {name: self._claims(name) for name in self._by_name()}
            self._load_all([kept for kept, _ in claims.values()])
            self._entries = {key: info for name, (kept, dups) in claims.items() for key, info
                             in [(name, self._loaded[kept.name, kept.value]), *dups.items()]}
            self._warn_broken(self._entries)
        return {**self._entries, **self._local}

    def _lookup(self, name: str) -> PluginInfo | None:
        """The plugin called ``name`` (None if unknown), importing no other entry point; a
        duplicate's "name [package]" is known to the listing only."""
        if name in self._local or self._entries is not None:  # known already
            return self._local.get(name) or self._entries.get(name)
        if name not in self._by_name():
            return self.entries().get(name) if name.endswith("]") else None
        kept, dups = self._claims(name)
        self._load_all([kept])
        self._warn_broken(dups)
        return self._loaded[kept.name, kept.value]

    def _warn_broken(self, found: dict[str, PluginInfo]) -> None:
        """A ``RuntimeWarning`` per broken plugin, once per process (as xarray's backends)."""
        for key, info in found.items():
            if not info.ok and (key, info.error) not in self._warned:
                self._warned.add((key, info.error or ""))
                warnings.warn(f"{self.kind} plugin {key!r} ({info.target}, package "
                              f"{info.package}) failed to load and is left out: {info.error}",
                              RuntimeWarning, stacklevel=stacklevel_outside_mrfpe())

    def register(self, name: str, obj: Any) -> None:
        """Register ``obj`` in this process only (tests, notebooks)."""
        self._validate(obj)
        self._local[name] = PluginInfo(name, f"{obj.__module__}:{obj.__qualname__}",
                                       "(local)", "", first_doc_line(obj), obj)

    def unregister(self, name: str) -> None:
        self._local.pop(name, None)

    def available(self) -> dict[str, PluginInfo]:
        """The working plugins, by name."""
        return {k: v for k, v in self.entries().items() if v.ok}

    def broken(self) -> dict[str, PluginInfo]:
        """The broken plugins, by name, each with its error."""
        return {k: v for k, v in self.entries().items() if not v.ok}

    def names(self) -> list[str]:
        """Names of the working plugins, sorted."""
        return sorted(self.available())

    def errors(self) -> dict[str, str]:
        """Broken plugins: ``{name: reason}``."""
        return {k: v.error or "" for k, v in self.broken().items()}

    def label(self, info: PluginInfo) -> str:
        """``sampler plugin 'x' (module:attr, package dist 1.0)``, for messages."""
        version = f" {info.version}" if info.version else ""
        return f"{self.kind} plugin {info.name!r} ({info.target}, package {info.package}{version})"

    def info(self, name: str) -> PluginInfo:
        """The working plugin registered as ``name``, importing no other entry point;
        ``ValueError`` if unknown (listing the names) or broken (naming it, and why)."""
        info = self._lookup(name)
        if info is None:
            known = (self.available() if self._entries is not None
                     else {*self._by_name(), *self._local})
            names = ", ".join(sorted(known)) or "(none)"
            raise ValueError(f"unknown {self.kind} {name!r}; available: {names}")
        if not info.ok:
            raise ValueError(f"{self.label(info)} is broken: {info.error}")
        return info

    def get(self, name: str | type) -> Any:
        """The object registered as ``name`` (:meth:`info`), or ``name`` itself if it is a
        class, validated (``TypeError``): xarray's ``engine=`` takes a class the same way."""
        if inspect.isclass(name):
            self._validate(name)
            return name
        if not isinstance(name, str):
            raise ValueError(f"{self.kind} name must be a string or a class; got {name!r}")
        return self.info(name).obj

    @contextmanager
    def calling(self, info: PluginInfo) -> Iterator[None]:
        """Run plugin ``info``'s code: a third-party one's ``ValueError`` gets :meth:`label` as a
        prefix, anything else (``sys.exit`` too) becomes a :class:`PluginError` naming it; a
        built-in's pass as they are (they are mrfpe's own)."""
        try:
            yield
        except (Exception, SystemExit) as exc:
            if is_builtin(info):
                raise
            if isinstance(exc, ValueError):
                raise ValueError(f"{self.label(info)}: {one_line(str(exc))}") from exc
            raise PluginError(f"{self.label(info)} failed: {type(exc).__name__}: "
                              f"{one_line(str(exc))}") from exc

    def table(self, extra: Callable[[PluginInfo], str] | None = None, *,
              width: int | None = WIDTH, verbose: bool = False) -> str:
        """A plain-text table of the plugins (name, package, description, ``width`` wide), with
        ``extra(info)`` before a description (a distance's parameters); ``verbose``: versions."""
        rows = []
        for info in self.entries().values():
            desc = info.description if info.ok else f"BROKEN: {info.error}"
            if extra is not None and info.ok:
                desc = f"{extra(info)}  {desc}".strip()
            row = (info.name, info.package, info.version, plain(desc))
            rows.append(row if verbose else row[:2] + row[3:])
        if not rows:
            return f"no {self.kind}s registered under {self.group!r}"
        head = ("name", "package", "version", "description")
        return table(head if verbose else head[:2] + head[3:], rows, width=width)

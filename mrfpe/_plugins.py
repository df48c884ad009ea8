"""Entry-point registries shared by samplers and distances.

Modelled on xarray's backend plugins: every extension (built-in or third-party)
is a plain class registered under an entry-point group in some package's
``pyproject.toml``. Discovery imports each entry point once, validates its
interface, and records failures as *broken* entries instead of raising (a
``sys.exit`` on import included), so one bad plugin never takes down the others
or the command line. A plugin that registers a built-in's name is listed as
broken and warned about, naming both distributions; the built-in keeps the name,
whatever the order of ``sys.path``.

Plugin modules must import heavy optional dependencies lazily (inside
``run``/``__call__``), so that listing stays cheap.
"""

from __future__ import annotations

import importlib.metadata as md
import inspect
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from mrfpe._caller import stacklevel_outside_mrfpe
from mrfpe._terminal import WIDTH, plain, table

__all__ = ["PluginInfo", "Registry"]


@dataclass(frozen=True)
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


#: The distribution whose entry points are the built-ins: their names cannot be taken over.
BUILTIN_PACKAGE = "mrfpe"


def _is_builtin(info: PluginInfo) -> bool:
    return info.package == BUILTIN_PACKAGE and info.target.startswith(f"{BUILTIN_PACKAGE}.")


def first_doc_line(obj: Any) -> str:
    """The first non-empty line of ``obj``'s docstring ('' if none)."""
    doc = inspect.getdoc(obj) or ""
    return next((line.strip() for line in doc.splitlines() if line.strip()), "")


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


class Registry:
    """Discover, validate and look up the plugins of one entry-point group.

    Parameters
    ----------
    group
        Entry-point group, e.g. ``"mrfpe.samplers"``.
    kind
        Human name used in messages, e.g. ``"sampler"``.
    validate
        Called with the loaded object; raises ``TypeError`` (or any exception)
        with a message when the object does not implement the interface.
    """

    def __init__(self, group: str, kind: str, validate: Callable[[Any], None]):
        self.group = group
        self.kind = kind
        self._validate = validate
        self._entries: dict[str, PluginInfo] | None = None
        self._local: dict[str, PluginInfo] = {}
        self._warned: set[tuple[str, str]] = set()  # (name, error) already warned about

    # -- discovery -------------------------------------------------------
    def _load(self, ep: md.EntryPoint) -> PluginInfo:
        dist = getattr(ep, "dist", None)
        package = dist.metadata["Name"] if dist is not None else "?"
        version = dist.version if dist is not None else "?"
        try:
            obj = ep.load()
            self._validate(obj)
        except (Exception, SystemExit) as exc:  # a broken plugin must not break discovery,
            # nor end the process by calling sys.exit on import
            return PluginInfo(ep.name, ep.value, package, version, "", None,
                              f"{type(exc).__name__}: {exc}")
        return PluginInfo(ep.name, ep.value, package, version, first_doc_line(obj), obj)

    def entries(self, refresh: bool = False) -> dict[str, PluginInfo]:
        """Every plugin of the group, broken ones included, by name."""
        if self._entries is None or refresh:
            found: dict[str, PluginInfo] = {}
            seen: set[tuple[str, str]] = set()
            for ep in sorted(md.entry_points(group=self.group), key=lambda e: e.name):
                if (ep.name, ep.value) in seen:  # same dist seen twice on sys.path
                    continue
                seen.add((ep.name, ep.value))
                info = self._load(ep)
                if ep.name in found:
                    kept, dup = found[ep.name], info
                    if _is_builtin(dup) and not _is_builtin(kept):
                        kept, dup = dup, kept  # a built-in name is never taken over
                    msg = (f"duplicate {self.kind} name {ep.name!r}: registered by "
                           f"{kept.package} {kept.version} ({kept.target}) and {dup.package} "
                           f"{dup.version} ({dup.target}); {kept.package}'s is kept")
                    found[ep.name] = kept
                    found[f"{ep.name} [{dup.package}]"] = PluginInfo(
                        dup.name, dup.target, dup.package, dup.version, dup.description, None,
                        msg)
                    continue
                found[ep.name] = info
            self._entries = found
            self._warn_broken(found)
        return {**self._entries, **self._local}

    def _warn_broken(self, found: dict[str, PluginInfo]) -> None:
        """A ``RuntimeWarning`` per broken plugin, once per process (as xarray's backends)."""
        for key, info in found.items():
            if info.ok or (key, info.error) in self._warned:
                continue
            self._warned.add((key, info.error or ""))
            warnings.warn(f"{self.kind} plugin {key!r} ({info.target}, package {info.package}) "
                          f"failed to load and is left out: {info.error}", RuntimeWarning,
                          stacklevel=stacklevel_outside_mrfpe())

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

    def get(self, name: str | type) -> Any:
        """The plugin object registered as ``name``, or ``name`` itself if it is a class.

        A class is validated (as a plugin would be) and returned, so that callers
        can pass either a registered name or an unregistered class (xarray's
        ``engine=`` accepts a backend class the same way).

        Raises
        ------
        ValueError
            If ``name`` is neither a string nor a class, is unknown (the message
            lists the available plugins) or is broken.
        TypeError
            If ``name`` is a class that does not implement the interface.
        """
        if inspect.isclass(name):
            self._validate(name)
            return name
        if not isinstance(name, str):
            raise ValueError(f"{self.kind} name must be a string or a class; got {name!r}")
        entries = self.entries()
        info = entries.get(name)
        if info is None:
            names = ", ".join(sorted(self.available())) or "(none)"
            raise ValueError(f"unknown {self.kind} {name!r}; available: {names}")
        if not info.ok:
            raise ValueError(f"{self.kind} {name!r} is broken: {info.error}")
        return info.obj

    def table(self, extra: Callable[[PluginInfo], str] | None = None, *,
              width: int | None = WIDTH, verbose: bool = False) -> str:
        """A plain-text table of the plugins: name, package and description, wrapped to
        ``width`` columns, with ``extra(info)`` (details such as a distance's parameters)
        before the description; ``verbose`` adds the version."""
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

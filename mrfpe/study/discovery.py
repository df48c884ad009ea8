"""Where studies come from: installed ones (entry points), local files, paths.

Installed studies are registered under the entry-point group ``mrfpe.studies``
(:data:`GROUP`), each naming a module's ``STUDY`` object: mrfpe's own (the
thesis's experiments, :mod:`mrfpe.experiments`) in its ``pyproject.toml``, as
its samplers, models and distances are, and any other distribution's the same
way. The machinery never imports a study package: listing the names reads the
entry points' metadata only, :func:`get` imports the one study asked for, and
:func:`available` imports them all (through a :class:`~mrfpe._plugins.Registry`,
so that one broken study, or a distribution taking a built-in's name, is
reported and left out instead of breaking the rest).
"""

from __future__ import annotations

import dataclasses
import difflib
import hashlib
import importlib.metadata as md
import importlib.util
import os
import sys
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

from mrfpe._plugins import Registry
from mrfpe.study.spec import Study

__all__ = ["GROUP", "available", "get", "load_file", "registry"]

#: The entry-point group of installed studies (``name = "package.module:STUDY"``).
GROUP = "mrfpe.studies"


def _check_study(obj: Any) -> None:
    if not isinstance(obj, Study):
        raise TypeError(f"not a mrfpe.study.Study (a {type(obj).__name__}); an entry point "
                        f"of {GROUP!r} must name a module's STUDY = mrfpe.study.Study(...)")


#: The installed studies, by entry-point name (loaded by :func:`available` only).
registry = Registry(GROUP, "study", _check_study)


def _located(study: Any, where: str) -> Study:
    """``study`` with :attr:`Study.source` set to ``where`` (a changed copy)."""
    if not isinstance(study, Study):
        raise ValueError(f"{where} does not define STUDY = mrfpe.study.Study(...)")
    return dataclasses.replace(study, source=where)


def _study_of(module: ModuleType, where: str) -> Study:
    return _located(getattr(module, "STUDY", None), where)


def _installed(name: str, study: Any, target: str) -> Study:
    """An entry point's study, found where its module is; its name must be the entry's."""
    study = _located(study, target.split(":", 1)[0])
    if study.name != name:
        raise ValueError(f"entry point {name!r} of {GROUP!r} ({target}) names a study called "
                         f"{study.name!r}; the two names must agree")
    return study


class StudyFileError(ValueError):
    """A study file that does not import; :attr:`reason` is what went wrong in it."""

    def __init__(self, path: Path, reason: str):
        super().__init__(f"{path}: cannot load the study file: {reason}")
        self.reason = reason


def load_file(path: str | os.PathLike) -> Study:
    """Load a study from a Python file that defines ``STUDY``.

    A file that does not import (a ``SyntaxError``, an exception, a ``sys.exit``)
    raises ``ValueError`` naming it and the reason.
    """
    path = Path(path).resolve()
    if not path.is_file():
        raise FileNotFoundError(f"no study file {path}")
    mod_name = "mrfpe_user_study_" + hashlib.sha256(str(path).encode()).hexdigest()[:12]
    spec = importlib.util.spec_from_file_location(mod_name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[mod_name] = module  # so pickling and dataclasses can find it
    try:
        spec.loader.exec_module(module)
    except (Exception, SystemExit) as exc:  # a SyntaxError or a sys.exit in the file: name it
        sys.modules.pop(mod_name, None)
        raise StudyFileError(path, f"{type(exc).__name__}: {exc}") from None
    return _study_of(module, str(path))


def _local_dir() -> Path:
    return Path.cwd() / "studies"


def _entry_points(name: str | None = None) -> list[md.EntryPoint]:
    """The group's entry points (all, or those called ``name``), without importing any."""
    eps = md.entry_points(group=GROUP) if name is None else md.entry_points(group=GROUP,
                                                                             name=name)
    return list(eps)


def _installed_names() -> list[str]:
    return sorted({ep.name for ep in _entry_points()})


def _get_installed(name: str) -> Study:
    """The installed study ``name``, importing its module only.

    Registered once (the usual case), its entry point is loaded directly; claimed by
    several distributions, the registry decides as it does for samplers (the built-in
    keeps its name).
    """
    eps = _entry_points(name)
    if len({ep.value for ep in eps}) == 1:
        ep = eps[0]
        try:
            obj = ep.load()
        except (Exception, SystemExit) as exc:  # a broken study: say which and why
            raise ValueError(f"study {name!r} ({ep.value}) is broken: "
                             f"{type(exc).__name__}: {exc}") from None
        return _installed(name, obj, ep.value)
    info = registry.entries()[name]
    if not info.ok:
        raise ValueError(f"study {name!r} is broken: {info.error}")
    return _installed(name, info.obj, info.target)


def available(broken: dict[str, str] | None = None) -> dict[str, Study]:
    """Installed studies, then ``./studies/<name>/study.py`` (a local one shadows an
    installed one of the same name).

    A study that fails to load is left out; pass a dict as ``broken`` to
    receive ``{name: error}`` for those.
    """
    found: dict[str, Study] = {}

    def add(name: str, load: Callable[[], Study]) -> None:
        try:
            found[name] = load()
        except (Exception, SystemExit) as exc:  # one broken study must not hide the others
            if broken is not None:
                broken[name] = getattr(exc, "reason", f"{type(exc).__name__}: {exc}")

    for key, info in registry.entries().items():
        if info.ok:
            add(key, lambda key=key, info=info: _installed(key, info.obj, info.target))
        elif broken is not None:
            broken[key] = info.error or ""
    local = _local_dir()
    if local.is_dir():
        for path in sorted(local.glob("*/study.py")):
            add(path.parent.name, lambda path=path: load_file(path))
    return found


def _names() -> list[str]:
    local = _local_dir()
    extra = [p.parent.name for p in local.glob("*/study.py")] if local.is_dir() else []
    return sorted({*_installed_names(), *extra})


def get(name: str) -> Study:
    """The study called ``name``, or loaded from ``name`` if it is a path to a ``.py`` file."""
    if name.endswith(".py") or os.sep in name:
        return load_file(name)
    local = _local_dir() / name / "study.py"
    if local.is_file():
        return load_file(local)
    if name in _installed_names():
        return _get_installed(name)
    names = _names()
    near = difflib.get_close_matches(name, names, n=1)
    hint = f" (did you mean {near[0]!r}?)" if near else ""
    raise ValueError(f"unknown study {name!r}{hint}; available: {', '.join(names) or '(none)'}")

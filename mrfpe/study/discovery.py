"""Where studies come from: the built-in modules of :mod:`mrfpe.studies`, local files, paths."""

from __future__ import annotations

import difflib
import hashlib
import importlib
import importlib.util
import os
import pkgutil
import sys
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

from mrfpe.study.spec import Study

__all__ = ["available", "get", "load_file"]


def _study_of(module: ModuleType, where: str) -> Study:
    study = getattr(module, "STUDY", None)
    if not isinstance(study, Study):
        raise ValueError(f"{where} does not define STUDY = mrfpe.study.Study(...)")
    object.__setattr__(study, "source", where)
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


def _builtin_names() -> list[str]:
    import mrfpe.studies as pkg

    helpers = set(getattr(pkg, "HELPER_MODULES", ()))
    return sorted(i.name for i in pkgutil.iter_modules(pkg.__path__)
                  if not i.name.startswith("_") and i.name not in helpers)


def available(broken: dict[str, str] | None = None) -> dict[str, Study]:
    """Built-in studies, then ``./studies/<name>/study.py`` (a local one shadows a built-in).

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

    for name in _builtin_names():
        mod = f"mrfpe.studies.{name}"
        add(name, lambda mod=mod: _study_of(importlib.import_module(mod), mod))
    local = _local_dir()
    if local.is_dir():
        for path in sorted(local.glob("*/study.py")):
            add(path.parent.name, lambda path=path: load_file(path))
    return found


def _names() -> list[str]:
    local = _local_dir()
    extra = [p.parent.name for p in local.glob("*/study.py")] if local.is_dir() else []
    return sorted({*_builtin_names(), *extra})


def get(name: str) -> Study:
    """The study called ``name``, or loaded from ``name`` if it is a path to a ``.py`` file."""
    if name.endswith(".py") or os.sep in name:
        return load_file(name)
    local = _local_dir() / name / "study.py"
    if local.is_file():
        return load_file(local)
    if name in _builtin_names():
        return _study_of(importlib.import_module(f"mrfpe.studies.{name}"),
                         f"mrfpe.studies.{name}")
    names = _names()
    near = difflib.get_close_matches(name, names, n=1)
    hint = f" (did you mean {near[0]!r}?)" if near else ""
    raise ValueError(f"unknown study {name!r}{hint}; available: {', '.join(names) or '(none)'}")

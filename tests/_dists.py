"""Installed distributions made up for the plugin tests: a dist-info and modules on a path.

``importlib.metadata`` finds a distribution by its ``NAME-VERSION.dist-info`` directory on
``sys.path``, so a temporary directory prepended to the path (or given as ``PYTHONPATH`` to
a child process) installs plugins for real: their entry points, package and version are
what a user's would be.
"""

from __future__ import annotations

import re
import textwrap
import warnings
from collections.abc import Iterator
from pathlib import Path

import pytest


def make_dist(root: Path, name: str, modules: dict[str, str],
              entry_points: dict[str, dict[str, str]]) -> Path:
    """Write distribution ``name`` 1.0 under ``root``: ``modules`` (module name -> source)
    and ``entry_points`` (group -> {entry name: "module:attr"})."""
    for module, source in modules.items():
        (root / f"{module}.py").write_text(textwrap.dedent(source))
    info = root / f"{name}-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text("".join(
        f"[{group}]\n" + "".join(f"{k} = {v}\n" for k, v in eps.items()) + "\n"
        for group, eps in entry_points.items()))
    return root


def unique(request: pytest.FixtureRequest, stem: str) -> str:
    """A module name for this test alone: a module stays in ``sys.modules`` once imported."""
    return stem + "_" + re.sub(r"\W", "_", request.node.name)


def refresh_all() -> None:
    """Rediscover every registry (after a test's distributions left ``sys.path``)."""
    import mrfpe.distances
    import mrfpe.models
    import mrfpe.samplers

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for module in (mrfpe.samplers, mrfpe.distances, mrfpe.models):
            module.registry.entries(refresh=True)


def on_sys_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """Body of a ``site`` fixture: a directory on ``sys.path``, ahead of mrfpe, for
    :func:`make_dist`; the registries are rediscovered without it afterwards."""
    root = tmp_path / "site"
    root.mkdir()
    monkeypatch.syspath_prepend(str(root))
    yield root
    monkeypatch.undo()
    refresh_all()

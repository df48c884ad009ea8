"""The trials of a resolved study: cells × repetitions, each with its own seed and file stem."""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass
from itertools import product
from typing import Any

import numpy as np

from mrfpe.budget import check_memory
from mrfpe.study.config import canonical
from mrfpe.study.resolve import config_hash
from mrfpe.study.spec import Study

__all__ = ["Task", "tasks", "trial_seed"]


def _cell_words(cell: Mapping[str, Any]) -> tuple[int, ...]:
    if not cell:
        return ()
    digest = hashlib.sha256(canonical(dict(cell)).encode()).digest()
    return tuple(int.from_bytes(digest[i:i + 4], "little") for i in range(0, 16, 4))


def trial_seed(study_seed: int, repeat: int, cell: Mapping[str, Any] = ()) -> int:
    """The integer seed of one trial (63 bits).

    ``SeedSequence(study_seed, spawn_key=(repeat, *words(cell)))``, with
    ``words`` four 32-bit words of a hash of the cell; for an empty cell this
    is child ``repeat`` of ``SeedSequence(study_seed).spawn(n)``.
    """
    ss = np.random.SeedSequence(study_seed, spawn_key=(int(repeat), *_cell_words(dict(cell))))
    return int(ss.generate_state(1, dtype=np.uint64)[0] >> np.uint64(1))


@dataclass(frozen=True)
class Task:
    """One trial of a resolved study: its cell, repetition, config, seed and file."""

    index: int
    cell: dict
    repeat: int
    config: dict
    seed: int
    hash: str
    stem: str


def _stem(cell: Mapping[str, Any], repeat: int) -> str:
    def clean(v: Any) -> str:
        s = str(v)
        return "".join(c if c.isalnum() or c in ".+-" else "_" for c in s)

    return "".join(f"{k}={clean(v)}," for k, v in cell.items()) + f"repeat={repeat:04d}"


#: Memory one trial's bookkeeping takes before it runs (its config, hash and names): a
#: trial count beyond the memory budget is refused before the list is built.
TASK_BYTES = 4096


def tasks(study: Study, config: Mapping[str, Any]) -> list[Task]:
    """Every trial of ``config`` (resolved), repetition-major, cells in grid order.

    A trial's config is ``config`` specialised to its cell, without ``n_trials`` and the
    study's summary-only settings (:attr:`~mrfpe.study.Study.summary_keys`).
    """
    skip = {*study.grid, "n_trials", *study.summary_keys}
    base = {k: v for k, v in config.items() if k not in skip}
    cells = [dict(zip(study.grid, vals)) for vals in product(*(config[k] for k in study.grid))]
    n = len(cells) * int(config["n_trials"])
    check_memory(TASK_BYTES * n, f"study {study.name!r} with {n} trials ({config['n_trials']} "
                 f"repetitions of {len(cells)} cells)", "lower --trials")
    out = []
    for repeat in range(config["n_trials"]):
        for cell in cells:
            tcfg = {**base, **cell}
            seed_cell = {k: v for k, v in cell.items() if k not in study.shared_seed}
            out.append(Task(len(out), cell, repeat, tcfg,
                            trial_seed(config["seed"], repeat, seed_cell),
                            config_hash(study, tcfg), _stem(cell, repeat)))
    return out

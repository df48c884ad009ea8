"""Shared pieces of the synthetic-data studies (thesis 7.2): settings, problems, traces.

Public, for your own studies (``docs/studies.md``): :data:`SETTINGS` -- the
declared settings the synthetic studies share, with their thesis defaults
(:data:`DEFAULTS`) and reduced ``--quick`` values (:data:`QUICK`) --
:func:`settings` to pick and re-default some, :func:`problem_from_config`,
:func:`make_problem`, :func:`sample_traced` and the distance helpers.

A *problem* is one synthetic scene (7.2 steps 2-4: random surface, random
light at infinity, random true parameters b^n, range labels), the target built
on it, the true parameters in the unit cube (7.1-7.2) and the target's global
maximiser (:func:`mrfpe.targets.maximise`). Distances are Euclidean in the
unit cube, as the thesis's "MAP dist" ((ρ_d, ρ_s, 2α) for Ward, (R_d, R_s,
n/25) for Phong). Every convergence study reports a sampler's distance to the
truth *and* to the maximiser: a pseudolikelihood's maximum need not sit on
the truth, and the two errors have different causes.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import xarray as xr

from mrfpe.study.spec import Setting

__all__ = [
    "DEFAULTS",
    "DEFAULT_SURFACES",
    "QUICK",
    "SETTINGS",
    "SURFACES",
    "Problem",
    "check_runs",
    "check_sampler_options",
    "child_seeds",
    "distance",
    "first_reach",
    "make_problem",
    "maximiser",
    "non_negative",
    "positive",
    "problem_from_config",
    "sample_traced",
    "sampler_names",
    "settings",
    "weight_variance",
]

#: The thesis tests each model on its own best surface type (7.2): Ward on
#: smooth thin-plate-spline surfaces, (isotropic) anisotropic Phong on jagged ones.
DEFAULT_SURFACES = {"ward": "smooth", "phong": "jagged"}
#: Surface types of :func:`mrfpe.brdf.synthetic.make_scene`.
SURFACES = ("smooth", "jagged")


# -- declared settings ---------------------------------------------------------------------


def _brdf_names() -> tuple[str, ...]:
    import mrfpe.brdf

    return mrfpe.brdf.names()


def _target_names() -> tuple[str, ...]:
    import mrfpe.targets

    return mrfpe.targets.names()


def sampler_names() -> list[str]:
    import mrfpe.samplers

    return list(mrfpe.samplers.available())


def positive(value: Any) -> None:
    """``check`` for a number, or a list of numbers, that must be > 0."""
    for v in value if isinstance(value, list) else [value]:
        if not v > 0:
            raise ValueError(f"must be > 0; got {v!r}")


def non_negative(value: float) -> None:
    """``check`` for a number that must be >= 0."""
    if not value >= 0:
        raise ValueError(f"must be >= 0; got {value!r}")


def _shape(value: list) -> None:
    if len(value) != 2 or not all(isinstance(v, int) and v >= 2 for v in value):
        raise ValueError(f"must be [rows, cols], two integers >= 2; got {value!r}")


def _unit_range(value: list) -> None:
    if len(value) != 2 or not 0.0 <= value[0] < value[1] <= 1.0:
        raise ValueError(f"must be [lo, hi] with 0 <= lo < hi <= 1; got {value!r}")


def _surfaces(value: dict) -> None:
    bad = {k: v for k, v in value.items() if v not in SURFACES}
    if bad:
        raise ValueError(f"surface types must be {' or '.join(SURFACES)}; got {bad}")


def check_sampler_options(sampler: str, options: Mapping[str, Any]) -> None:
    """``ValueError`` unless sampler ``sampler`` accepts ``options`` (builds it: cheap)."""
    import mrfpe.samplers

    try:
        mrfpe.samplers.get(sampler)(**options)
    except TypeError as exc:
        raise ValueError(f"sampler {sampler!r}: {exc}") from None
    except ValueError as exc:
        raise ValueError(f"sampler {sampler!r}: {exc}") from None


def check_runs(runs: Mapping[str, Any]) -> None:
    """``check`` of a ``runs`` setting: ``{label: {"sampler": NAME, **options}}``."""
    if not runs:
        raise ValueError("needs at least one run")
    for label, opts in runs.items():
        if not isinstance(opts, dict) or "sampler" not in opts:
            raise ValueError(f"run {label!r} must be an object with a \"sampler\" key; "
                             f"got {opts!r}")
        opts = dict(opts)
        check_sampler_options(opts.pop("sampler"), opts)


#: The settings the synthetic-scene studies share, with the thesis's values (7.2-7.4).
SETTINGS: dict[str, Setting] = {s.name: s for s in (
    Setting("brdf", ["ward", "phong"], "reflectance models, one grid column each",
            choices=_brdf_names),
    Setting("n_labels", [10, 20, 30, 40], "range labels per node (B)", check=positive),
    Setting("surfaces", dict(DEFAULT_SURFACES),
            "surface type per model: smooth (thin-plate spline) or jagged (7.2)",
            choices=_brdf_names, check=_surfaces),
    Setting("shape", [100, 100], "image size [rows, cols] in pixels", check=_shape),
    Setting("noise", 0.0, "standard deviation of Gaussian image noise", check=non_negative),
    Setting("target", "pls", "target built on each scene (7.5-7.7)", choices=_target_names),
    Setting("target_options", {}, "keyword options of the target, e.g. {\"dtype\": "
            "\"float32\"}"),
    Setting("truth_range", [0.1, 0.9],
            "true parameters drawn uniformly from [lo, hi] on each unit-cube axis",
            check=_unit_range),
    Setting("maximiser_grid", 20, "grid points per axis seeding the search for the "
            "target's global maximiser", check=positive),
)}
#: Their defaults: the one place the synthetic studies' common configuration lives.
DEFAULTS: dict[str, Any] = {k: s.default for k, s in SETTINGS.items()}
#: Reduced values for ``--quick`` (tiny scenes, two repetitions, one label count).
QUICK: dict[str, Any] = {"n_trials": 2, "n_labels": [10], "shape": [12, 12],
                         "maximiser_grid": 8}


def check_surfaces(config: Mapping[str, Any]) -> None:
    """Study ``check``: every model in ``brdf`` has a surface type in ``surfaces``."""
    brdfs = config["brdf"] if isinstance(config["brdf"], list) else [config["brdf"]]
    missing = [b for b in brdfs if b not in config["surfaces"]]
    if missing:
        raise ValueError(f"setting 'surfaces' has no surface type for {', '.join(missing)}; "
                         f"add it, e.g. --set 'surfaces={{\"{missing[0]}\": \"smooth\"}}'")


def check_target_options(config: Mapping[str, Any]) -> None:
    """Study ``check``: the targets accept their ``target_options``.

    Builds each target with its options on a 4×4 scene with 2 labels (well
    under a second): the options are only checked against a scene, and a
    misspelt option must not wait for a trial's expensive setup to fail.
    """
    if "target" in config:
        by_target = {config["target"]: config["target_options"]}
    else:  # {target: options}, as in target_bias
        by_target = dict(config["target_options"])
    by_target = {k: v for k, v in by_target.items() if v}
    if not by_target:
        return
    import mrfpe

    brdf = config.get("brdf", "ward")
    brdf = brdf[0] if isinstance(brdf, list) else brdf
    model = mrfpe.brdf.get(brdf)
    scene = mrfpe.brdf.synthetic.make_scene(
        brdf=brdf, theta=model.to_natural(np.full(model.d, 0.5)), shape=(4, 4), n_labels=2,
        seed=0)
    for name, options in by_target.items():
        if not isinstance(options, dict):
            raise ValueError(f"setting 'target_options': options of {name!r} must be an "
                             f"object; got {options!r}")
        try:
            mrfpe.targets.get(name, scene, **options)
        except mrfpe.targets.MemoryBudgetError:
            continue  # about this probe scene, not the options: each trial checks its own
        except (TypeError, ValueError) as exc:
            raise ValueError(f"setting 'target_options': {exc}") from None


def check_problem(config: Mapping[str, Any]) -> None:
    """Study ``check``: :func:`check_surfaces` and :func:`check_target_options`."""
    if "surfaces" in config:
        check_surfaces(config)
    check_target_options(config)


def settings(*names: str, **defaults: Any) -> list[Setting]:
    """The shared :data:`SETTINGS` called ``names``, with some defaults replaced.

    ``settings("shape", "n_labels", n_labels=20)`` declares the image shape
    and a single label count of 20 (the type follows the new default).
    """
    unknown = sorted(set(defaults) - set(names))
    if unknown:
        raise ValueError(f"settings(): defaults for undeclared names {unknown}")
    return [dataclasses.replace(SETTINGS[n], default=defaults[n]) if n in defaults
            else SETTINGS[n] for n in names]


def problem_from_config(config: Mapping[str, Any], seed: int,
                        brdf: str | None = None) -> Problem:
    """:func:`make_problem` with a trial config's shared settings (``brdf``: config's)."""
    brdf = config["brdf"] if brdf is None else brdf
    return make_problem(brdf, seed, surface=config["surfaces"][brdf], shape=config["shape"],
                        n_labels=config["n_labels"], noise=config["noise"],
                        target=config["target"], target_options=config["target_options"],
                        truth_range=config["truth_range"],
                        maximiser_grid=config["maximiser_grid"])


# -- problems ------------------------------------------------------------------------------


def child_seeds(seed: int, n: int) -> list[int]:
    """``n`` independent integer seeds from one trial seed (``SeedSequence.spawn``)."""
    return [int(c.generate_state(1, dtype=np.uint64)[0] >> np.uint64(1))
            for c in np.random.SeedSequence(seed).spawn(n)]


@dataclass
class Problem:
    """A synthetic scene, its target, the truth and the target's maximiser (unit cube)."""

    scene: Any
    target: Any
    truth: np.ndarray
    maximiser: np.ndarray | None
    maximiser_log_prob: float
    truth_log_prob: float

    def dataset(self) -> xr.Dataset:
        """Truth, maximiser and scene facts as variables of a trial Dataset."""
        names = list(self.target.param_names)
        data = {
            "truth": (("param",), self.truth),
            "truth_log_prob": ((), self.truth_log_prob),
            "light": (("xyz",), np.asarray(self.scene.light.direction, dtype=float)),
        }
        if self.maximiser is not None:
            data.update({
                "maximiser": (("param",), self.maximiser),
                "maximiser_log_prob": ((), self.maximiser_log_prob),
                "maximiser_to_truth": ((), float(distance(self.maximiser, self.truth))),
            })
        return xr.Dataset(data, coords={"param": names, "xyz": ["x", "y", "z"]})


def make_problem(brdf: str, seed: int, *, surface: str, shape: Sequence[int], n_labels: int,
                 noise: float = 0.0, target: str = "pls", target_options: dict | None = None,
                 truth: Sequence[float] | None = None, truth_range: Sequence[float] = (0.1, 0.9),
                 maximiser_grid: int | None = 20) -> Problem:
    """Build one problem from ``seed`` (truth, then scene, then maximiser streams).

    ``truth`` (unit cube) is drawn uniformly from ``truth_range`` per
    parameter when not given; ``maximiser_grid=None`` skips the maximiser.
    """
    import mrfpe

    s_truth, s_scene, s_max = child_seeds(seed, 3)
    model = mrfpe.brdf.get(brdf)
    if truth is None:
        lo, hi = truth_range
        u = np.random.default_rng(s_truth).uniform(lo, hi, model.d)
    else:
        u = np.asarray(truth, dtype=float)
    scene = mrfpe.brdf.synthetic.make_scene(brdf=brdf, theta=model.to_natural(u),
                                       shape=tuple(shape), n_labels=n_labels, surface=surface,
                                       noise=noise, seed=s_scene)
    tgt = mrfpe.targets.get(target, scene, **(target_options or {}))
    truth_lp = float(tgt.log_prob(u[None])[0])
    if maximiser_grid is None:
        return Problem(scene, tgt, u, None, np.nan, truth_lp)
    mx, mlp = maximiser(tgt, maximiser_grid, s_max, u)
    return Problem(scene, tgt, u, mx, mlp, truth_lp)


def maximiser(target: Any, grid: int, seed: int, truth: Any) -> tuple[np.ndarray, float]:
    """:func:`mrfpe.targets.maximise` on the evenly spaced ``grid``³ points plus the truth.

    The truth is one more start for the local refinement: a peak narrower than
    the grid spacing can otherwise be missed (measured: on a 100×100 Ward scene
    the 20³ grid alone returned a point 23 nats below the truth's value). The
    result is still the best local maximum found, wherever it lies.
    """
    import mrfpe
    from mrfpe.targets.maximise import grid_points

    pts = np.vstack([grid_points(target.bounds, grid), np.asarray(truth, dtype=float)[None]])
    mx, mlp = mrfpe.targets.maximise(target, grid=pts, seed=seed)
    return np.asarray(mx, dtype=float), float(mlp)


def distance(a: Any, b: Any) -> np.ndarray:
    """Euclidean distance along the last axis (unit cube)."""
    return np.linalg.norm(np.asarray(a, dtype=float) - np.asarray(b, dtype=float), axis=-1)


def sample_traced(name: str, target: Any, seed: int, **config: Any) -> tuple[xr.Dataset,
                                                                             np.ndarray]:
    """Run sampler ``name``; also return the cumulative target evaluations after each step."""
    import mrfpe

    evals: list[float] = []
    post = mrfpe.sample(name, target, seed=seed,
                        callback=lambda step, info: evals.append(float(info["n_target_evals"])),
                        **config)
    evals_arr = np.asarray(evals, dtype=float)
    if evals_arr.size != post.sizes["step"]:  # a sampler that skips its callback on some steps
        evals_arr = np.full(post.sizes["step"], np.nan)
    return post, evals_arr


def weight_variance(post: xr.Dataset) -> np.ndarray:
    """Variance of the normalised weights of every stored iteration (the thesis's "var")."""
    lw = post["history_log_weight"].values
    return np.exp(lw).var(axis=1)


def highest_weight(post: xr.Dataset) -> np.ndarray:
    """(step, param) particle of largest weight at every stored iteration (7.4.1 step 6's MAP)."""
    lw = post["history_log_weight"].values
    top = np.argmax(np.where(np.isnan(lw), -np.inf, lw), axis=1)
    return post["history_theta"].values[np.arange(lw.shape[0]), top]


def first_reach(dist: np.ndarray, evals: np.ndarray, level: float) -> float:
    """Target evaluations when ``dist`` (per step) first falls to ``level`` (NaN if never)."""
    hit = np.flatnonzero(np.asarray(dist) <= level)
    return float(evals[hit[0]]) if hit.size else float("nan")

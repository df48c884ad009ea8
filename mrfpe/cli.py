"""The mrfpe command line: demo, samplers, distances, models, estimate, compare, study, warmup.

Every command checks all of its inputs (files readable and of the right kind,
output paths writable, settings known and well-typed) before its first
expensive step. Usage and input errors print one line, ``mrfpe CMD: error:
...``, and exit with status 2; ``--debug`` shows the traceback instead. A
third-party plugin that fails prints one such line naming it, and exits with 1.
"""

from __future__ import annotations

import argparse
import errno
import sys
from collections.abc import Sequence
from typing import Any

from mrfpe.validation import check_keywords, keyword_names

__all__ = ["build_parser", "main", "parse_assignments"]

#: Exit status for usage and input errors (argparse's own convention).
USAGE_ERROR = 2


def parse_assignments(items: Sequence[str], option: str = "--set") -> dict[str, Any]:
    """Parse ``key=value`` strings (values read as JSON where possible) for ``option``.

    Raises ``ValueError`` naming ``option`` for an item without ``=``; :func:`main`
    reports it and exits 2.
    """
    from mrfpe.study.config import parse_assignments as parse

    try:
        return parse(items)
    except ValueError as exc:
        raise ValueError(f"{option}: {exc}") from None


def _load_scene(path: str) -> Any:
    from mrfpe.brdf.scene import Scene

    return Scene.load(path)


def _load_posterior(path: str) -> Any:
    from mrfpe import posterior as P

    post = P.load(path)
    try:
        P.validate(post)
    except ValueError as exc:
        raise ValueError(f"{path}: not a posterior file (written by mrfpe estimate / "
                         f"posterior.save): {exc}") from None
    return post


def _demo(args: argparse.Namespace) -> int:
    from mrfpe.demo import main as demo_main

    return demo_main(out_dir=args.out, quick=args.quick, seed=args.seed)


def _warmup(args: argparse.Namespace) -> int:
    from mrfpe.warmup import main as warmup_main

    return warmup_main()


def _samplers(args: argparse.Namespace) -> int:
    from mrfpe.samplers import registry

    print(registry.table(verbose=args.verbose))
    return 0


def _distances(args: argparse.Namespace) -> int:
    from mrfpe.distances import registry

    print(registry.table(verbose=args.verbose))
    return 0


def _models(args: argparse.Namespace) -> int:
    from mrfpe.models import registry

    print(registry.table(verbose=args.verbose))
    return 0


def _check_output(out: Any, inputs: Sequence[Any], force: bool) -> None:
    """Refuse an ``--out`` that is one of the inputs, or (without ``--force``) an existing
    file that is not a posterior: nothing is overwritten that was not meant to be."""
    import os

    from mrfpe.netcdf import read_attrs

    if not os.path.lexists(out):
        return
    for path in inputs:
        if os.path.samefile(out, path):
            raise ValueError(f"--out {out} is the input file {path}; writing there would "
                             "replace it: choose another --out")
    if force:
        return
    try:
        attrs = read_attrs(out, "posterior")
    except ValueError:
        attrs = {}
    if "sampler" not in attrs or "mrfpe_version" not in attrs:
        raise ValueError(f"--out {out} exists and is not a posterior file written by mrfpe; "
                         "refusing to overwrite it (pass --force to replace it)")


def _estimate(args: argparse.Namespace) -> int:
    import numpy as np

    import mrfpe
    from mrfpe.netcdf import check_readable, check_writable
    from mrfpe.posterior import save
    from mrfpe.samplers import get as get_sampler
    from mrfpe.validation import check_seed

    # Everything cheap first: settings, paths, the scene; sampling last.
    settings = parse_assignments(args.set, "--set")
    target_options = parse_assignments(args.target_option, "--target-option")
    if args.target not in mrfpe.targets.names():
        raise ValueError(f"--target: unknown target {args.target!r}; available: "
                         f"{', '.join(mrfpe.targets.names())}")
    seed = check_seed(args.seed, "--seed")
    cls = get_sampler(args.sampler)
    check_keywords(settings, keyword_names(cls.__init__, 1), f"sampler {args.sampler!r}",
                   "--set")
    cls(**settings)  # the settings' values checked now, before the scene is read
    scene_path = check_readable(args.scene, "scene")
    out = check_writable(args.out, "--out posterior")
    _check_output(out, [scene_path], args.force)
    scene = _load_scene(args.scene)
    try:
        target = mrfpe.targets.get(args.target, scene, **target_options)
    except TypeError as exc:
        raise ValueError(f"--target-option: {exc}") from None
    # through mrfpe.sample: BLAS on one thread, the result checked before it is written
    post = mrfpe.sample(args.sampler, target, seed=seed, progress=not args.quiet, **settings)
    save(post, out)  # atomic: a kill mid-write never leaves a partial posterior
    m = post["map_theta"].isel(step=-1).values
    natural = np.asarray(target.to_natural(m), dtype=float).reshape(-1)
    names = [str(p) for p in post["param"].values]
    print(f"posterior ({post.sizes['sample']} samples, ESS {post.attrs['diag_ess']:.0f}, "
          f"{post.attrs['wall_time_s']:.1f} s) -> {out}")
    print("MAP (unit cube)  " + "  ".join(f"{n}={v:.4f}" for n, v in zip(names, m)))
    print("MAP (natural)    " + "  ".join(f"{n}={v:.4g}" for n, v in zip(names, natural)))
    return 0


def _compare(args: argparse.Namespace) -> int:
    from mrfpe.distances import distance
    from mrfpe.distances import get as get_distance

    params = parse_assignments(args.param, "--param")
    cls = get_distance(args.distance)
    check_keywords(params, keyword_names(cls.__call__, 3), f"distance {args.distance!r}",
                   "--param")
    a, b = _load_posterior(args.a), _load_posterior(args.b)
    # the result checked (a number, not NaN, not negative if declared nonnegative), and a
    # plugin's own failure reported as the plugin's, naming it
    value = distance(args.distance, a, b, **params)
    what = "similarity" if getattr(cls, "kind", "distance") == "similarity" else "distance"
    print(f"{args.distance} {what} between {args.a} and {args.b}: {value} (no unit)")
    return 0


def _study(args: argparse.Namespace) -> int:
    from mrfpe.study import cli as study_cli

    return study_cli(args)


def _version() -> str:
    from mrfpe._version import __version__

    return f"mrfpe {__version__}"


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``mrfpe`` (every option with its help text)."""
    p = argparse.ArgumentParser(prog="mrfpe", description=__doc__.split("\n\n")[0])
    verbose = argparse.ArgumentParser(add_help=False)
    verbose.add_argument("--verbose", "-v", action="store_true",
                         help="full descriptions, wrapped, instead of one line each")
    p.add_argument("--version", action="version", version=_version())
    p.add_argument("--debug", action="store_true",
                   help="show the full traceback of an error instead of one line")
    sub = p.add_subparsers(dest="command", required=True)
    _add_demo_and_warmup(sub)
    _add_listings(sub, verbose)
    _add_estimate(sub)
    _add_compare(sub)
    _add_study(sub, verbose)
    return p


def _add_demo_and_warmup(sub: Any) -> None:
    d = sub.add_parser("demo", help="estimate the reflectance of a synthetic surface: scene -> "
                       "PMC posterior -> verdict, figure and report",
                       description="Render a synthetic Ward scene with known parameters, "
                       "sample its pseudolikelihood with PMC (1000 particles x 20 "
                       "iterations, about 15 s on two idle cores once the kernels are "
                       "compiled), say how close "
                       "it came to the truth, and write scene.nc, posterior.nc, posterior.png "
                       "and report.md into --out.")
    d.add_argument("--out", default="mrfpe-demo",
                   help="output directory, created if needed (default: mrfpe-demo)")
    d.add_argument("--quick", action="store_true",
                   help="40x40 scene, 10 labels, 1000 particles x 20 iterations (a few "
                        "seconds; no thesis figure to compare with)")
    d.add_argument("--seed", type=int, default=0,
                   help="seed of the scene, the true parameters and the sampler (default: 0)")
    d.set_defaults(func=_demo)

    w = sub.add_parser("warmup", help="compile the numerical kernels once, ahead of any run",
                       description="Compile the pseudolikelihood kernels into numba's "
                       "on-disk cache, so that the first demo or estimate starts at once "
                       "(otherwise the first run compiles them, 20-60 s).")
    w.set_defaults(func=_warmup)


def _add_listings(sub: Any, verbose: argparse.ArgumentParser) -> None:
    s = sub.add_parser("samplers", help="list registered samplers", parents=[verbose])
    s.set_defaults(func=_samplers)
    s = sub.add_parser("distances", help="list registered distances", parents=[verbose])
    s.set_defaults(func=_distances)
    s = sub.add_parser("models", help="list registered models (declared MRFs)",
                       parents=[verbose])
    s.set_defaults(func=_models)


def _add_estimate(sub: Any) -> None:
    e = sub.add_parser("estimate", help="sample a target built from a scene netCDF file")
    e.add_argument("scene", help="scene netCDF file (Scene.save, or scene.nc of mrfpe demo)")
    e.add_argument("--sampler", default="pmc",
                   help="sampler name, see 'mrfpe samplers' (default: pmc)")
    e.add_argument("--target", default="pls",
                   help="target built on the scene: pls, fit or pml (default: pls)")
    e.add_argument("--out", required=True,
                   help="posterior netCDF file to write (its directory must exist)")
    e.add_argument("--seed", type=int, default=0, help="sampler seed (default: 0)")
    e.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="sampler setting, value as JSON where it parses (repeatable), "
                        "e.g. --set n_samples=1000")
    e.add_argument("--target-option", action="append", default=[], metavar="KEY=VALUE",
                   help="target option (repeatable), e.g. --target-option dtype=float32")
    e.add_argument("--quiet", action="store_true", help="no progress bar")
    e.add_argument("--force", action="store_true",
                   help="overwrite --out even if it exists and is not a posterior file")
    e.set_defaults(func=_estimate)


def _add_compare(sub: Any) -> None:
    c = sub.add_parser("compare", help="distance between two posterior netCDF files")
    c.add_argument("a", help="first posterior netCDF file (mrfpe estimate --out)")
    c.add_argument("b", help="second posterior netCDF file")
    c.add_argument("--distance", default="bhattacharyya",
                   help="distance name, see 'mrfpe distances' (default: bhattacharyya)")
    c.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                   help="distance parameter (repeatable), e.g. --param alpha=0.7")
    c.set_defaults(func=_compare)


#: The positional argument of every ``mrfpe study`` command but ``list``.
_STUDY_NAME = "study name (see 'mrfpe study list') or path to a .py file"


def _add_study(sub: Any, verbose: argparse.ArgumentParser) -> None:
    st = sub.add_parser("study", help="reproducible studies of the thesis's experiments")
    st_sub = st.add_subparsers(dest="study_command", required=True)
    st_sub.add_parser("list", help="list studies with their trial counts and full-run times",
                      parents=[verbose])
    sh = st_sub.add_parser("show", help="a study's settings: type, default, --quick value, "
                                        "meaning")
    sh.add_argument("name", help=_STUDY_NAME)
    _add_study_run(st_sub)
    _add_study_report(st_sub)
    _add_study_verify(st_sub)
    st.set_defaults(func=_study)


def _add_study_run(st_sub: Any) -> None:
    r = st_sub.add_parser("run", help="run (or resume) a study")
    r.add_argument("name", help=_STUDY_NAME)
    r.add_argument("--quick", action="store_true",
                   help="the study's reduced settings (same code path, about a minute)")
    r.add_argument("--trials", type=int, default=None,
                   help="repetitions per grid cell (overrides the n_trials setting)")
    r.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a setting, value as JSON where it parses (repeatable); "
                        "'mrfpe study show NAME' lists them")
    r.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run the trials on this dask.distributed scheduler, e.g. "
                        "tcp://HOST:8786 (default: in this process)")
    r.add_argument("--out", default=None,
                   help="output directory (default: studies/NAME/out, or out-quick with "
                        "--quick); rerun with the same one to resume")
    r.add_argument("--force", action="store_true",
                   help="run even if --out holds another study's files (they are replaced "
                        "where names collide)")


def _add_study_report(st_sub: Any) -> None:
    rp = st_sub.add_parser("report", help="write a study's report from the trial files on "
                                          "disk, running nothing (complete cells only)")
    rp.add_argument("name", help=_STUDY_NAME)
    rp.add_argument("--quick", action="store_true", help="the study's reduced settings")
    rp.add_argument("--trials", type=int, default=None, help="repetitions per grid cell")
    rp.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="override a setting, as for 'run'")
    rp.add_argument("--out", default=None, help="output directory, as for 'run'")
    rp.add_argument("--partial", action="store_true",
                    help="also summarise cells with only some repetitions on disk")


def _add_study_verify(st_sub: Any) -> None:
    v = st_sub.add_parser(
        "verify", help="replay trial files of a results directory and compare them bit for "
                       "bit (exit 1 on any difference)",
        description="Run trials of a results directory again from what their files record "
                    "(config, cell, repetition, seed, numba threads) and compare every "
                    "variable and every attribute but the timings and the run's provenance "
                    "with the file, bit for bit. One verdict per trial; exit status 1 if any "
                    "trial differs, cannot be replayed or fails.")
    v.add_argument("name", help=_STUDY_NAME)
    v.add_argument("--out", default=None,
                   help="results directory holding trials/*.nc, e.g. docs/results/NAME "
                        "(default: studies/NAME/out)")
    v.add_argument("--count", type=int, default=None, metavar="K",
                   help="replay at most K trials (default: every trial file)")
    v.add_argument("--cheapest", action="store_true",
                   help="the trials with the smallest recorded trial_wall_time_s first")
    v.add_argument("--trial", action="append", default=[], metavar="STEM",
                   help="replay this trial (its file name without .nc; repeatable)")


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status (0 ok, 1 failed trials, a full disk or
    a failing plugin, 2 bad input)."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ValueError, FileNotFoundError) as exc:
        if args.debug:
            raise
        print(f"mrfpe {args.command}: error: {exc}", file=sys.stderr)
        return USAGE_ERROR
    except KeyboardInterrupt:
        if args.debug:
            raise
        print(f"mrfpe {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into a reader that stopped (e.g. | head)
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except Exception as exc:  # a bug or an environment failure, not bad input
        if args.debug:
            raise
        from mrfpe._plugins import PluginError

        # a full disk, or a third-party plugin failing (its message names it): say so
        if isinstance(exc, PluginError) or getattr(exc, "errno", None) in (errno.ENOSPC,
                                                                            errno.EDQUOT):
            print(f"mrfpe {args.command}: error: {exc}", file=sys.stderr)
            return 1
        print(f"mrfpe {args.command}: internal error: {type(exc).__name__}: {exc} "
              "(rerun with --debug for the traceback)", file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

"""The ``mrfpe`` command line: demo, samplers, distances, estimate, compare, study."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from typing import Any


def parse_assignments(items: Sequence[str]) -> dict[str, Any]:
    """Parse ``key=value`` strings; values are read as JSON where possible."""
    out: dict[str, Any] = {}
    for item in items:
        if "=" not in item:
            raise SystemExit(f"expected key=value, got {item!r}")
        key, raw = item.split("=", 1)
        try:
            out[key.strip()] = json.loads(raw)
        except json.JSONDecodeError:
            out[key.strip()] = raw
    return out


def _demo(args: argparse.Namespace) -> int:
    from mrfpe.demo import main as demo_main

    return demo_main(out_dir=args.out, quick=args.quick, seed=args.seed)


def _samplers(args: argparse.Namespace) -> int:
    from mrfpe.samplers import registry

    print(registry.table())
    return 0


def _distances(args: argparse.Namespace) -> int:
    from mrfpe.distances import registry

    print(registry.table())
    return 0


def _estimate(args: argparse.Namespace) -> int:
    import mrfpe
    from mrfpe.scene import Scene

    scene = Scene.load(args.scene)
    target = mrfpe.targets.get(args.target, scene, **parse_assignments(args.target_option))
    post = mrfpe.sample(args.sampler, target, seed=args.seed, progress=not args.quiet,
                        **parse_assignments(args.set))
    from mrfpe.posterior import save

    save(post, args.out)
    m = post["map_theta"].isel(step=-1).values
    print(f"MAP (sampling space): {m.round(4).tolist()}  -> {args.out}")
    return 0


def _compare(args: argparse.Namespace) -> int:
    import mrfpe
    from mrfpe.posterior import load

    a, b = load(args.a), load(args.b)
    print(mrfpe.distance(args.distance, a, b, **parse_assignments(args.param)))
    return 0


def _study(args: argparse.Namespace) -> int:
    from mrfpe import study

    return study.cli(args)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="mrfpe", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)

    d = sub.add_parser("demo", help="synthetic Ward scene -> PMC posterior -> report and figures")
    d.add_argument("--out", default="mrfpe-demo", help="output directory (default: mrfpe-demo)")
    d.add_argument("--quick", action="store_true", help="smaller scene and fewer samples")
    d.add_argument("--seed", type=int, default=0)
    d.set_defaults(func=_demo)

    s = sub.add_parser("samplers", help="list registered samplers")
    s.set_defaults(func=_samplers)
    s = sub.add_parser("distances", help="list registered distances")
    s.set_defaults(func=_distances)

    e = sub.add_parser("estimate", help="sample a target built from a scene netCDF file")
    e.add_argument("scene")
    e.add_argument("--sampler", default="pmc")
    e.add_argument("--target", default="pls")
    e.add_argument("--out", required=True)
    e.add_argument("--seed", type=int, default=0)
    e.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="sampler setting (repeatable)")
    e.add_argument("--target-option", action="append", default=[], metavar="KEY=VALUE")
    e.add_argument("--quiet", action="store_true")
    e.set_defaults(func=_estimate)

    c = sub.add_parser("compare", help="distance between two posterior netCDF files")
    c.add_argument("a")
    c.add_argument("b")
    c.add_argument("--distance", default="bhattacharyya")
    c.add_argument("--param", action="append", default=[], metavar="KEY=VALUE")
    c.set_defaults(func=_compare)

    st = sub.add_parser("study", help="reproducible studies of the thesis's experiments")
    st_sub = st.add_subparsers(dest="study_command", required=True)
    st_sub.add_parser("list", help="list studies")
    r = st_sub.add_parser("run", help="run (or resume) a study")
    r.add_argument("name")
    r.add_argument("--quick", action="store_true")
    r.add_argument("--trials", type=int, default=None)
    r.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    r.add_argument("--scheduler", default=None, help="dask.distributed scheduler address")
    r.add_argument("--out", default=None)
    st.set_defaults(func=_study)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ValueError, FileNotFoundError) as exc:
        print(f"mrfpe {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

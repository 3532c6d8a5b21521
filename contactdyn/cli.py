"""The ``contactdyn`` command line: thin dispatch to plain functions."""

from __future__ import annotations

import argparse
import sys

from .errors import ContactdynError

__all__ = ["main"]

EXIT_OK, EXIT_FAILED, EXIT_USAGE = 0, 1, 2


def _cmd_run(args: argparse.Namespace) -> int:
    from .scene import parse_override
    from .simulate import simulate

    overrides = dict(parse_override(s) for s in args.set)
    result = simulate(args.scene, overrides)
    s = result.stats
    print(f"{result.meta['name']}: {result.meta['duration']:g} s simulated in {s['wall_s']:.3f} s "
          f"(real-time factor {s['real_time_factor']:.1f}), {s['steps']} steps, {s['rhs_evals']} rhs evaluations, "
          f"{s['events']} events, {len(result.impacts)} impacts")
    for name in result.meta["contacts"]:
        F = result[f"contact.{name}.F_n"]
        print(f"  contact {name}: normal force peak {F.max():.4g} N, final {F[-1]:.4g} N")
    for imp in result.impacts:
        print(f"  impact t = {imp['t']:.6g} s on {imp['contact']}: FΔt = {imp['normal_impulse']:.6g} N·s, "
              f"F_fΔt = {imp['friction_impulse']} N·s, jammed = {imp['jammed']}")
    if args.out:
        path = result.save(args.out)
        print(f"  saved {path} and {path.with_suffix('.json')}")
    return EXIT_OK


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="contactdyn", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="simulate a scene", epilog="example: contactdyn run b1 --set solver.rtol=1e-6")
    run.add_argument("scene", help="scene file or name in sims/")
    run.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a scene key")
    run.add_argument("--out", help="save the run as OUT.npz + OUT.json")
    run.set_defaults(func=_cmd_run)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except ContactdynError as exc:
        print(f"contactdyn: error: {exc}", file=sys.stderr)
        return EXIT_USAGE if type(exc).__name__ in ("SceneError", "RobotError") else EXIT_FAILED


if __name__ == "__main__":
    sys.exit(main())

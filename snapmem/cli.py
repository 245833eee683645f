"""The ``snapmem`` command: a thin layer over the package.

Every command builds a scene from ``--set NAME=VALUE`` pairs and calls one driver. Bad input
is one line on stderr and exit code 2; ``--debug`` shows the traceback instead.
"""

from __future__ import annotations

import argparse
import logging
import sys

from .errors import SnapmemError, SolverError
from .scenes import SCENES, get_spec


class _Parser(argparse.ArgumentParser):
    def error(self, message):          # one line, exit 2, like every other bad input
        raise SnapmemError(message)


def parse_sets(pairs: list[str]) -> dict:
    """``["R=10", "nodes=51"]`` -> ``{"R": "10", "nodes": "51"}`` (values checked by the scene)."""
    out = {}
    for pair in pairs or []:
        name, sep, value = pair.partition("=")
        if not sep or not name.strip() or not value.strip():
            raise SnapmemError(f"--set {pair!r}: must be NAME=VALUE, e.g. --set nodes=201")
        out[name.strip()] = value.strip()
    return out


def cmd_scenes(args) -> int:
    for spec in SCENES.values():
        print(f"{spec.name}: {spec.doc}")
        for p in spec.parameters:
            default = "(derived)" if p.default is None else p.default
            unit = f" [{p.unit}]" if p.unit else ""
            print(f"    {p.name} = {default}{unit}  {p.doc}")
    return 0


def cmd_equilibrium(args) -> int:
    from .newton import equilibrium
    params = parse_sets(args.set)
    if args.pressure is not None:
        params["pressure"] = args.pressure
    scene = get_spec(args.scene).build(**params)
    eq = equilibrium(scene)
    for name, value in {"pressure": scene.resolve_loads(eq.loads)["pressure"], **eq.measures()}.items():
        print(f"{name}: {value:.10g}" if isinstance(value, float) else f"{name}: {value}")
    for line in eq.report.lines():
        print(line)
    return 0 if eq.converged else 1


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="snapmem", description="Snap-through of axisymmetric dielectric-elastomer membranes.")
    parser.add_argument("--debug", action="store_true", help="show tracebacks")
    parser.add_argument("-v", "--verbose", action="store_true", help="log solver progress")
    sub = parser.add_subparsers(dest="command", parser_class=_Parser)
    sub.required = True

    p = sub.add_parser("scenes", help="list scenes with their parameters, defaults and units")
    p.set_defaults(func=cmd_scenes)

    p = sub.add_parser("equilibrium", help="solve one equilibrium, loading from rest")
    p.add_argument("scene")
    p.add_argument("--set", action="append", metavar="NAME=VALUE", help="scene parameter (repeatable)")
    p.add_argument("--pressure", type=str, help="pressure (inside minus outside), scene units")
    p.set_defaults(func=cmd_equilibrium)
    return parser


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    debug = "--debug" in argv
    try:
        args = build_parser().parse_args(argv)
        logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                            format="%(levelname)s %(name)s: %(message)s")
        return args.func(args)
    except (SnapmemError, SolverError) as exc:
        if debug:
            raise
        print(f"snapmem: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("snapmem: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())

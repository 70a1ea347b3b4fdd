"""The `hydrotact` command: thin wrappers over the library, one module per command.

Each command module has `add_parser(subparsers)` (its flags, defaults and help) and
`run(args)`: parse, call one library function, print. Nothing here holds physics or
file logic, and no stage imports this package.

Every user error ends in one line, `hydrotact: error: ...`, naming the file, field or
value at fault, and exit status 2; never a traceback.
"""

import argparse
import sys

from .. import __version__
from .._errors import HydrotactError
from . import compare, contact, demo, field, fit, mesh, simulate

COMMANDS = (mesh, field, contact, simulate, fit, compare, demo)
"""The commands, in the order `hydrotact --help` lists them."""

# Planned, each its own module here once its library stage exists: generate
# (synthetic datasets), train and evaluate (the estimator), predict, export
# (microcontroller weights), design (barometer layouts).
FUTURE_COMMANDS = ("generate", "train", "evaluate", "predict", "export", "design")


def make_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hydrotact",
        description="Differentiable simulation and system identification for barometric tactile sensors.",
    )
    parser.add_argument("--version", action="version", version=f"hydrotact {__version__}")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in COMMANDS:
        command.add_parser(subparsers).set_defaults(run=command.run)
    return parser


def main(argv=None) -> int:
    args = make_parser().parse_args(argv)
    try:
        import jax

        jax.config.update("jax_enable_x64", True)
        args.run(args)
    except HydrotactError as error:
        print(f"hydrotact: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("hydrotact: interrupted", file=sys.stderr)
        return 130
    return 0

"""The `hydrotact` command: thin wrappers over the library, one module per command.

Each command module has `add_parser(subparsers)` (its flags, defaults and help) and
`run(args)`: parse, call one library function, print. Nothing here holds physics or
file logic, and no stage imports this package.

Every user error ends in one line, `hydrotact: error: ...`, naming the file, field or
value at fault, and exit status 2; never a traceback. A command whose computation
stops using the CPU for good (a stall of XLA's CPU runtime: nothing else waits so)
ends after STALL_S seconds with one line naming what it was waiting for, and exit
status 3 (:mod:`hydrotact._stall`); not while it waits for a Ray cluster.
"""

import argparse
import contextlib
import os
import re
import sys
import warnings

from .. import __version__
from .._errors import HydrotactError, HydrotactWarning
from .._files import cache_dir
from .._stall import STALL_S, StallGuard, doing
from . import compare, contact, demo, design, evaluate, export, field, fit, generate, mesh, predict, simulate, train

COMMANDS = (mesh, field, contact, simulate, fit, compare, generate, train, evaluate, predict, export, design, demo)
"""The commands, in the order `hydrotact --help` lists them."""

class Parser(argparse.ArgumentParser):
    """argparse, with one-line usage errors and negative numbers as values.

    A usage error is one line, `hydrotact: error: COMMAND: ...`, pointing to the
    command's --help (argparse prints the whole usage first). A value such as `-1e5`
    or `-1mm,0,0.4mm` is a value, not an unknown option (argparse takes only `-5` and
    `-0.5` so), so that `--modulus -1e5` is refused for its sign, not as a missing
    argument. (Subcommands' parsers are of this class too.)"""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-\.?\d")

    def error(self, message):
        command = self.prog.partition(" ")[2]
        self.exit(2, f"hydrotact: error: {command + ': ' if command else ''}{message}; see '{self.prog} --help'\n")


def make_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="hydrotact",
        description="Differentiable simulation and system identification for barometric tactile sensors.",
    )
    parser.add_argument("--version", action="version", version=f"hydrotact {__version__}")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in COMMANDS:
        command.add_parser(subparsers).set_defaults(run=command.run)
    return parser


def _stalled(what: str, seconds: float) -> None:
    print(
        f"hydrotact: error: stuck: no CPU used for {seconds:.0f} s while {what}; XLA's CPU runtime is waiting for work that never "
        "comes. Run the command again; if it stalls again, please report it with this line",
        file=sys.stderr,
        flush=True,
    )
    os._exit(3)


def main(argv=None) -> int:
    args = make_parser().parse_args(argv)
    doing(f"running hydrotact {args.command}")
    guard = contextlib.nullcontext() if getattr(args, "ray", None) else StallGuard(_stalled, STALL_S)
    try:
        import jax

        jax.config.update("jax_enable_x64", True)
        # Compiled programs persist between runs (a small dataset's first run spends
        # about two thirds of its two minutes compiling): an LRU cache of 2 GiB, locked
        # (filelock) against other runs; $JAX_COMPILATION_CACHE_DIR, if set, wins.
        if not jax.config.jax_compilation_cache_dir:
            jax.config.update("jax_compilation_cache_dir", str(cache_dir() / "xla"))
            jax.config.update("jax_compilation_cache_max_size", 2**31)
        with warnings.catch_warnings():
            warnings.simplefilter("always", HydrotactWarning)
            show = warnings.showwarning

            def one_line(message, category, *rest, **keywords):
                if issubclass(category, HydrotactWarning):
                    print(f"hydrotact: warning: {message}", file=sys.stderr)
                else:
                    show(message, category, *rest, **keywords)

            warnings.showwarning = one_line
            with guard:
                args.run(args)
    except HydrotactError as error:
        print(f"hydrotact: error: {error}", file=sys.stderr)
        return 2
    except OSError as error:  # the file system failed under a checked path (disk full, removed folder)
        name = error.filename if error.filename is not None else "output"
        print(f"hydrotact: error: {name}: {error.strerror or error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("hydrotact: interrupted", file=sys.stderr)
        return 130
    return 0

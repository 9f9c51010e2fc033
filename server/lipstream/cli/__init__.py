"""The ``lipstream`` command line.

Subcommands: build-demo, train, synth, serve, inspect, retarget, bench, loadtest, bridge,
capture, align, path. Each command's parser and handler are one module,
``add_<command>_parser`` adding the command to the subcommands with its handler as ``run``:
here in ``lipstream.cli``, except for a command whose work is a package of its own, which
keeps its command module beside that work (``lipstream.loadtest.command``,
``lipstream.capture.command``). Every option has a help line
(``lipstream <command> --help``); ``--version`` prints the version. A user-facing failure
prints one line (``error [code]: where: message``) and exits 2.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from .._version import __version__
from ..capture.command import add_capture_parser
from ..config import load_settings
from ..errors import LipstreamError
from ..loadtest.command import add_loadtest_parser
from .align import add_align_parser
from .bench import add_bench_parser
from .bridge import add_bridge_parser
from .build_demo import add_build_demo_parser
from .inspect import add_inspect_parser
from .path import add_path_parser
from .retarget import add_retarget_parser
from .serve import add_serve_parser
from .synth import add_synth_parser
from .train import add_train_parser

if TYPE_CHECKING:
    from .commands import Commands, Handler

COMMANDS: tuple[Callable[[Commands], None], ...] = (
    add_build_demo_parser,
    add_train_parser,
    add_synth_parser,
    add_serve_parser,
    add_inspect_parser,
    add_retarget_parser,
    add_bench_parser,
    add_loadtest_parser,
    add_bridge_parser,
    add_capture_parser,
    add_align_parser,
    add_path_parser,
)
"""Each command's parser, in the order ``lipstream --help`` lists them."""


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="lipstream", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"lipstream {__version__}")
    commands = parser.add_subparsers(dest="command", required=True)
    for add_parser in COMMANDS:
        add_parser(commands)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    args.command_line = ["lipstream", *(sys.argv[1:] if argv is None else argv)]
    run: Handler = args.run
    try:
        run(args, load_settings())
    except LipstreamError as error:
        print(
            f"error [{error.code}]: {error.where + ': ' if error.where else ''}{error.message}",
            file=sys.stderr,
        )
        return 2
    except OSError as error:
        print(f"error [io_error]: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    return 0

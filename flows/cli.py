"""The ``gcpfree`` command line: it only registers the subcommands, one module each in
``flows/commands/`` (``add_parser(sub)``, ``run(args)``), and runs the one asked for.

Importing it loads no Prefect, Dask or NumPy (``gcpfree --help`` answers at once): each
command's ``run`` imports its flow when it runs.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from flows._env import configure_environment, one_line_errors
from flows.commands import archive as archive_command
from flows.commands import block as block_command
from flows.commands import coregister as coregister_command
from flows.commands import dsm as dsm_command
from flows.commands import evaluate as evaluate_command
from flows.commands import fill_voids as fill_voids_command
from flows.commands import info as info_command
from flows.commands import localize as localize_command
from flows.commands import orient as orient_command
from flows.commands import ortho as ortho_command
from flows.commands import ortho_compare as ortho_compare_command
from flows.commands import pair as pair_command
from flows.commands import prepare_reference as prepare_reference_command
from flows.commands import project as project_command
from flows.commands import relative as relative_command
from flows.commands import report as report_command
from flows.commands import scenes as scenes_command
from flows.commands import serve as serve_command
from flows.commands import simulate as simulate_command
from flows.commands._pair import OneLineParser


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="gcpfree",
        description="Orient satellite stereo pairs without ground control points, using SRTM.",
    )
    parser.add_argument("--verbose", action="store_true",
                        help="show Prefect's and Dask's progress logs (off by default)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in COMMAND_MODULES.values():
        module.add_parser(sub)
    return parser


# the registry, in the order of ``gcpfree --help``
COMMAND_MODULES = {"prepare-reference": prepare_reference_command,
                   "simulate": simulate_command, "info": info_command,
                   "project": project_command, "localize": localize_command,
                   "relative": relative_command, "evaluate": evaluate_command,
                   "coregister": coregister_command, "dsm": dsm_command,
                   "orient": orient_command, "pair": pair_command, "block": block_command,
                   "report": report_command, "ortho": ortho_command,
                   "ortho-compare": ortho_compare_command, "fill-voids": fill_voids_command,
                   "scenes": scenes_command, "archive": archive_command,
                   "serve": serve_command}
COMMANDS = {name: m.run for name, m in COMMAND_MODULES.items()}


def main(argv: Sequence[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # --help (0), or a one-line argument error (2)
        return int(exc.code or 0)
    configure_environment(verbose=args.verbose)
    from core.errors import GcpFreeError

    try:
        with one_line_errors():
            return COMMANDS[args.command](args)
    except GcpFreeError as exc:
        print(f"gcpfree {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("gcpfree: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())

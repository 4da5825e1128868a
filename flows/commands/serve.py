"""``gcpfree serve``: the archive reprocessed on a schedule (a served Prefect deployment)."""

from __future__ import annotations

import argparse

from flows.commands.archive import add_archive_arguments, check_archive_args, flow_parameters

DEFAULT_CRON = "0 2 * * *"
DEFAULT_NAME = "nightly-archive"


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "serve",
        help="reprocess the archive on a cron schedule (a Prefect deployment served here)",
        description=(
            "Register a deployment of the reprocess-archive flow with a cron schedule on the "
            "Prefect server named by PREFECT_API_URL (start one with `prefect server start "
            "--host 127.0.0.1` and set PREFECT_API_URL=http://127.0.0.1:4200/api), then run its "
            "scheduled runs in this process until stopped (Ctrl-C or SIGTERM). Each run is "
            "`gcpfree archive` with the arguments given here: only pairs missing or failed are "
            "processed. Runs can also be started from the UI or with `prefect deployment run "
            "reprocess-archive/NAME`. prefect.yaml describes the same deployment for a work "
            "pool."),
    )
    add_archive_arguments(p)
    p.add_argument("--cron", default=DEFAULT_CRON, metavar="EXPR",
                   help=f"cron schedule, 5 fields (default \"{DEFAULT_CRON}\": 02:00 daily)")
    p.add_argument("--timezone", default="UTC",
                   help="time zone of the cron schedule (IANA name, default UTC)")
    p.add_argument("--name", default=DEFAULT_NAME,
                   help=f"deployment name (default {DEFAULT_NAME})")


def check_schedule(cron: str, timezone: str):  # -> CronSchedule
    """The schedule, or one line saying what is wrong with it."""
    from prefect.client.schemas.schedules import CronSchedule
    from pydantic import ValidationError

    from core.errors import InputError

    try:
        return CronSchedule(cron=cron, timezone=timezone)
    except ValidationError as exc:
        what = "; ".join(e["msg"] for e in exc.errors())
        raise InputError(f"--cron {cron!r} / --timezone {timezone!r}: {what}; give 5 cron "
                         "fields such as \"0 2 * * *\" and an IANA time zone") from exc


def run(args: argparse.Namespace) -> int:
    from prefect.settings import PREFECT_API_URL

    from core.errors import InputError

    check_archive_args(args)
    check_schedule(args.cron, args.timezone)
    if not PREFECT_API_URL.value():
        raise InputError("gcpfree serve needs a running Prefect server for its schedule: start "
                         "`prefect server start --host 127.0.0.1` and set "
                         "PREFECT_API_URL=http://127.0.0.1:4200/api")
    from prefect.schedules import Cron

    from flows.reprocess_archive import reprocess_archive

    print(f"serving               reprocess-archive/{args.name} on \"{args.cron}\" "
          f"({args.timezone}) at {PREFECT_API_URL.value()}; stop with Ctrl-C", flush=True)
    reprocess_archive.serve(
        name=args.name, schedule=Cron(args.cron, timezone=args.timezone),
        parameters=flow_parameters(args), tags=["gcpfree", "archive"],
        description=f"gcpfree archive of {args.catalog} into {args.out}",
        print_starting_message=False)
    return 0

"""``gcpfree orient``: a stereo pair oriented with no GCP, from SRTM alone (steps 1-4)."""

from __future__ import annotations

import argparse
from collections.abc import Callable

from flows.commands._pair import (
    add_orientation_arguments,
    add_pair_arguments,
    add_reference_arguments,
    add_run_arguments,
    check_pair,
    check_reference_sigma,
    orientation_params,
)


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "orient",
        help="orient a stereo pair without GCPs: relative, relative DEM, SRTM surface "
             "matching, absolute",
        description=(
            "Relative orientation of the pair, its relative DEM by dense matching, windows of "
            "that DEM around the tie points matched to the reference DEM (SRTM) into simulated "
            "GCPs, and the absolute orientation of both images on them (robust least squares, "
            "blunders rejected, optional lens self-calibration). Refuses terrain too flat to "
            "fix the position. The final DSM is the relative DEM's matches intersected again "
            "with the oriented models. Writes OUT/report.json, the oriented models OUT/left.json "
            "and OUT/right.json, OUT/gcps.json, OUT/windows.json, OUT/dsm.tif (ellipsoidal) "
            "and OUT/dsm_egm96.tif, OUT/relative_dem.tif and OUT/relative/. With --sar, "
            "SAR-optical GCPs too (OUT/sar_points.json), which also orient flat terrain."),
    )
    add_orient_arguments(p)


def add_orient_arguments(p: argparse.ArgumentParser,
                         more: Callable[[argparse.ArgumentParser], None] = lambda p: None
                         ) -> None:
    """The options of ``orient`` (and of ``pair``, whose own ``more`` adds before
    ``--workers --no-progress --out``)."""
    add_pair_arguments(p)
    add_reference_arguments(p, use="the ground the pair is oriented to (required, or "
                                   "--dem-dir)")
    add_orientation_arguments(p)
    more(p)
    add_run_arguments(p)


def orient_params(args: argparse.Namespace, command: str,
                  check_more: Callable[[argparse.Namespace], None] = lambda args: None):
    """The orientation's parameters (:class:`flows.orient.OrientParams`) of ``orient`` and
    ``pair``, every input checked before the flow starts: the pair (:func:`check_pair`),
    ``check_more`` (a command's own inputs), the orientation's
    (:func:`orientation_params`)."""
    checked = check_pair(args)
    check_more(args)
    return orientation_params(args, command, checked)


def run(args: argparse.Namespace) -> int:
    from flows._env import prefect_api

    check_reference_sigma(args)  # refused in a line, before the server boots
    with prefect_api() as api:  # a temporary Prefect server boots meanwhile
        params = orient_params(args, "orient")
        from flows.orient import orient_flow

        api.ready()
        outcome = orient_flow(params)
        print("\n".join(outcome.lines()))
    return 0

"""Flow ``fill-voids`` (``gcpfree fill-voids``, :mod:`flows.commands.fill_voids`): an SRTM
tile's voids filled from the oriented DSM.

SRTM tile + DSM -> the DSM resampled onto the tile's nodes in orthometric heights -> each void
filled with the DSM plus the SRTM-minus-DSM difference measured around it (delta surface) ->
the tile in its own format and grid, ``OUT.json`` beside it.
"""

from __future__ import annotations

from prefect import flow

from tasks.evaluation.void_fill import (
    FillOptions,
    FillSummary,
    fill_tile_voids,
    write_fill_report,
)


@flow(name="fill-voids", log_prints=True)
def fill_voids_flow(options: FillOptions) -> FillSummary:
    """Fill and write the tile, then its summary."""
    summary = fill_tile_voids(options)
    write_fill_report(summary)
    return summary

"""Flows ``ortho`` and ``ortho-compare`` (``gcpfree ortho``, ``gcpfree ortho-compare``;
:mod:`flows.commands.ortho`, :mod:`flows.commands.ortho_compare`).

``ortho``: image + model + DEM -> the output grid (local UTM zone or ``--crs``, cells of the
image's GSD or ``--resolution``, cut to the DEM) -> each 1024-cell tile: heights from the DEM,
image positions from the model on a checked sparse lattice (< 0.01 px), the image resampled
-> ``OUT`` (COG with nodata and overviews), ``OUT.json`` and the optional occlusion mask.

``ortho-compare``: two orthos on one lattice -> windows every STEP cells over the common area
-> each searched for by normalised cross-correlation with a sub-pixel peak -> ``OUT`` (JSON:
median and 95th percentile of the discrepancy in px and m, every window) and the optional map
(COG) and quiver plot (PNG): the quality control that needs no ground truth.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from prefect import flow

from core.ortho.ortho_compare import CompareConfig
from tasks.io.sensors import load_model
from tasks.ortho.compare import CompareSummary, compare_orthos, plan_compare
from tasks.ortho.inputs import describe_dem
from tasks.ortho.orthorectify import OrthoOptions, OrthoSummary, orthorectify, plan_ortho


@flow(name="ortho", log_prints=True)
def ortho_flow(options: OrthoOptions) -> OrthoSummary:
    """Read the model and the DEM, plan the grid, write the tiles."""
    loaded = load_model(options.image, model=options.model, band=options.band)
    dem = describe_dem(options.dem, options.dem_vertical)
    plan = plan_ortho(loaded, dem, options.resolution_m, options.epsg,
                      options.occlusion_mask is not None)
    return orthorectify(plan, options.out, options.config, options.workers,
                        options.occlusion_mask)


@dataclass(frozen=True)
class CompareOptions:
    """Inputs of :func:`ortho_compare_flow` (see ``gcpfree ortho-compare --help``)."""

    left: Path
    right: Path
    out: Path
    map: Path | None = None
    quiver: Path | None = None
    compare: CompareConfig = field(default_factory=CompareConfig)
    workers: int | None = None


@flow(name="ortho-compare", log_prints=True)
def ortho_compare_flow(options: CompareOptions) -> CompareSummary:
    """Plan the windows over the common area, correlate them, write the products."""
    plan = plan_compare(options.left, options.right, options.compare)
    return compare_orthos(plan, options.out, options.map, options.quiver, options.workers)

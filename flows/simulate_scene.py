"""Flows: render a SPOT-like stereo pair with known truth over a real DEM (``simulate-scene``),
or a block of R x C scenes over K dates of one world (``simulate-block``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from prefect import flow

from core.simulation.block import BlockLayout
from core.simulation.scene import ErrorConfig, error_config
from tasks.io.geoid import BUNDLED_SRTM_DIR
from tasks.simulate.block import (
    BlockOptions,
    BlockSummary,
    build_block_radiance,
    define_block,
    make_block_checkpoints,
    render_block_images,
    summarize_block,
    write_block_metadata,
)
from tasks.simulate.sar import simulate_sar
from tasks.simulate.scene import (
    SimulationSummary,
    build_radiance,
    build_truth_surface,
    define_scene,
    make_checkpoints,
    render_image,
    summarize,
    write_spot_metadata,
)
from tasks.simulate.survey import make_lidar, make_reference

BUNDLED_DEM = BUNDLED_SRTM_DIR / "N44E005.hgt"


@dataclass(frozen=True)
class WorldParams:
    """What a simulated pair and a simulated block share: where, over which DEM, the preset
    and the errors of their images (see ``gcpfree simulate --help``)."""

    out: Path
    dem: Path = BUNDLED_DEM
    preset: str = "tiny"
    seed: int = 0
    lens: bool = False
    jitter: bool = False
    date_change: float = 0.0
    relief_factor: float = 1.0
    bits: int = 8
    center: tuple[float, float] | None = None
    dem_vertical: str = "auto"
    errors: str | None = None  # "realistic" or "simple"; None: the preset's default

    def error_config(self) -> ErrorConfig:
        """The errors the images carry: the preset's, or ``errors``, with the lens and jitter
        asked for."""
        return error_config(self.preset, self.errors, lens=self.lens, jitter=self.jitter)


@dataclass(frozen=True)
class SimulationParams(WorldParams):
    """Parameters of :func:`simulate_scene` (see ``gcpfree simulate --help``)."""

    lidar: bool = True
    sar: str | None = None  # "ers" or "s1": also a SAR product of the same world


@flow(name="simulate-scene", log_prints=True)
def simulate_scene(params: SimulationParams) -> SimulationSummary:
    """Scene and models -> truth surface -> radiance and image per date -> check points, lidar
    -> (with ``sar``) the SAR product of the same world."""
    out = Path(params.out)
    scene = define_scene(Path(params.dem), out, params.preset, params.seed, params.error_config(),
                         params.relief_factor, params.bits, params.date_change, params.center,
                         params.dem_vertical)
    write_spot_metadata(scene, out)
    scene = build_truth_surface(scene, out)
    for i in range(len(scene.image_names)):
        build_radiance(scene, out, i)
        render_image(scene, out, i)
    make_checkpoints(scene, out)
    make_reference(scene, out)
    if params.lidar:
        make_lidar(scene, out)
    if params.sar:
        simulate_sar(scene, out, params.sar)
    return summarize(scene, out)


@dataclass(frozen=True)
class BlockParams(WorldParams):
    """Parameters of :func:`simulate_block` (``gcpfree simulate --block RxC --dates K``)."""

    layout: BlockLayout = field(kw_only=True)
    flat_scene: str | None = None  # "r{row}c{col}": that scene's ground too flat


@flow(name="simulate-block", log_prints=True)
def simulate_block(params: BlockParams) -> BlockSummary:
    """Passes and images -> SPOT metadata -> truth surface -> radiance per date -> every image
    -> check points seen by two images or more -> the SRTM-like reference."""
    out = Path(params.out)
    opts = BlockOptions(
        params.layout, params.preset, params.seed,
        params.error_config(),
        params.relief_factor, params.bits, params.date_change, params.center,
        params.dem_vertical, params.flat_scene)
    scene = define_block(Path(params.dem), out, opts)
    write_block_metadata(scene, out)
    scene = build_truth_surface(scene, out)
    for d in range(params.layout.dates):
        build_block_radiance(scene, out, d)
        render_block_images(scene, out, d)
    make_block_checkpoints(scene, out)
    make_reference(scene, out)
    return summarize_block(scene, out)

"""Simulated scenes shared by the tests: each is rendered once per test session."""

from __future__ import annotations

from pathlib import Path

from core.simulation.scene import ErrorConfig, SceneDef
from tasks.geoid import BUNDLED_SRTM_DIR

DEM = BUNDLED_SRTM_DIR / "N44E005.hgt"
CENTRE = (5.25, 44.2)


def run_scene(out: Path, dem: Path = DEM, centre: tuple[float, float] | None = CENTRE,
              seed: int = 11, lidar: bool = True, lens: bool = True, jitter: bool = True,
              **kw: object) -> SceneDef:
    """The simulator's tasks run directly (no Prefect flow): the tiny preset into ``out``."""
    from tasks import simulate as S

    errors = ErrorConfig(lens=lens, jitter=jitter)
    scene = S.define_scene.fn(dem, out, "tiny", seed, errors, centre_lonlat=centre, **kw)
    S.write_spot_metadata.fn(scene, out)
    scene = S.build_truth_surface.fn(scene, out)
    for i in (0, 1):
        S.build_radiance.fn(scene, out, i)
        S.render_image.fn(scene, out, i)
    S.make_checkpoints.fn(scene, out)
    S.make_reference.fn(scene, out)
    if lidar:
        S.make_lidar.fn(scene, out)
    return scene

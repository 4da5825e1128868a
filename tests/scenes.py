"""Simulated scenes shared by the tests: each is rendered once per test session."""

from __future__ import annotations

from pathlib import Path

from core.simulation.scene import ErrorConfig, SceneDef
from tasks.io.geoid import BUNDLED_SRTM_DIR

DEM = BUNDLED_SRTM_DIR / "N44E005.hgt"
CENTRE = (5.25, 44.2)


def run_scene(out: Path, dem: Path = DEM, centre: tuple[float, float] | None = CENTRE,
              seed: int = 11, lidar: bool = True, lens: bool = True, jitter: bool = True,
              **kw: object) -> SceneDef:
    """The simulator's tasks run directly (no Prefect flow): the tiny preset into ``out``."""
    from tasks.simulate import scene as S
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


def dsm_against_truth(dsm_path: Path, truth_path: Path) -> tuple[float, float, int]:
    """Median and NMAD (m) of the DSM minus the truth DSM (both ellipsoidal, one UTM zone) at
    every valid DSM cell, and the number of cells."""
    import numpy as np
    import rasterio

    from core.dem import sample_bilinear
    from core.robust import nmad

    with rasterio.open(dsm_path) as src:
        z, t = src.read(1).astype(np.float64), src.transform
    with rasterio.open(truth_path) as src:
        truth, tt = src.read(1).astype(np.float64), src.transform
    rows, cols = np.nonzero(np.isfinite(z))
    x, y = t.c + (cols + 0.5) * t.a, t.f + (rows + 0.5) * t.e
    d = z[rows, cols] - sample_bilinear(truth, (tt.f - y) / -tt.e - 0.5, (x - tt.c) / tt.a - 0.5)
    d = d[np.isfinite(d)]
    return float(np.median(d)), nmad(d), int(d.size)

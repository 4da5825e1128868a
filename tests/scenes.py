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


def independent_reference(scene: Path, dest: Path, shift_m: tuple[float, float] = (8.0, 0.0),
                          noise_m: float = 4.0, correlation_m: float = 600.0,
                          canopy: float = 0.5, bias_m: float = 1.5, seed: int = 0
                          ) -> tuple[float, float]:
    """A reference made from ``scene``'s truth with nothing of the simulator's reference code
    (a defect both shared would not show), written as ``dest`` on the lattice of
    ``scene/reference.tif`` with its tags: the truth DTM plus ``canopy`` of what the truth DSM
    adds (C band sees part of the crowns and roofs), averaged over SRTM's 90 m footprint (an
    odd box), sampled at positions moved by ``shift_m`` (east, north: the reference shows the
    world moved by it), plus noise Gaussian-filtered to about ``correlation_m`` and scaled to
    ``noise_m``, plus ``bias_m``: the magnitudes by which SRTM differs from the world (Rodriguez
    et al. 2006: a few metres of noise correlated over hundreds of metres, a metre-level bias,
    a registration of some metres). Returns the shift."""
    import numpy as np
    import rasterio
    from pyproj import Transformer
    from scipy.ndimage import gaussian_filter, map_coordinates, uniform_filter

    rng = np.random.default_rng(seed)
    with rasterio.open(scene / "reference.tif") as r:
        profile, tr, shape, tags = r.profile, r.transform, r.shape, r.tags()
    with rasterio.open(scene / "truth" / "dtm.tif") as d:
        dtm, ttr, crs = d.read(1).astype(np.float64), d.transform, d.crs
    with rasterio.open(scene / "truth" / "dsm.tif") as d:
        dsm = d.read(1).astype(np.float64)
    box = int(round(90.0 / ttr.a)) | 1
    surface = uniform_filter(dtm + canopy * (dsm - dtm), size=box, mode="nearest")
    rows, cols = np.mgrid[0:shape[0], 0:shape[1]]
    lon, lat = tr.c + (cols + 0.5) * tr.a, tr.f + (rows + 0.5) * tr.e
    x, y = Transformer.from_crs(4326, crs, always_xy=True).transform(lon, lat)
    dx, dy = shift_m
    h = map_coordinates(surface, [(y - dy - ttr.f) / ttr.e - 0.5, (x - dx - ttr.c) / ttr.a - 0.5],
                        order=1, cval=np.nan)
    noise = gaussian_filter(rng.normal(size=shape), correlation_m / (abs(tr.e) * 111_320.0))
    h = h + noise_m * noise / noise.std() + bias_m
    profile.update(dtype="float32", nodata=np.nan)
    with rasterio.open(dest, "w", **profile) as out:
        out.write(h.astype(np.float32), 1)
        out.update_tags(**{**tags, "source": "tests/scenes.py independent_reference"})
    return float(dx), float(dy)

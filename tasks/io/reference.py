"""Tasks of the reference preparation: SRTM tiles + EGM96 -> ellipsoidal reference DEM (COG)."""

from __future__ import annotations

import io
import tempfile
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path

import dask.array as darr
import numpy as np
import rioxarray
import xarray as xr
from prefect import task

from core.geodesy import ARCSEC, BBox, metres_per_degree
from core.geoid import GeoidGrid
from core.jsonio import to_json
from tasks.io.dem import check_srtm_tiles
from tasks.io.geoid import load_geoid
from tasks.io.rasters import (
    CHUNK,
    atomic_write_bytes,
    atomic_write_text,
    cog_item,
    write_arrays_cog,
)
from tasks.io.srtm import SrtmTile, build_vrt, covered, find_tiles, mosaic_grid

VOID_VALID, VOID_SRTM, VOID_UNCOVERED = 0, 1, 2


@dataclass(frozen=True)
class ReferenceSummary:
    """What ``prepare_reference`` produced and what it found."""

    path: str
    void_mask_path: str
    bbox: tuple[float, float, float, float]
    width: int
    height: int
    res_arcsec: float
    tiles: tuple[str, ...]
    coverage_pct: float
    void_pct: float
    h_min_m: float
    h_max_m: float
    H_min_m: float
    H_max_m: float

    def to_json(self) -> str:
        return to_json(asdict(self), indent=2)

    def lines(self) -> list[str]:
        return [
            f"reference DEM  {self.path}",
            (f"grid           {self.width} x {self.height} px at {self.res_arcsec:g} arcsec, "
             f"{len(self.tiles)} SRTM tile(s): {', '.join(self.tiles)}"),
            f"coverage       {self.coverage_pct:.2f} % of the box has SRTM tiles",
            f"voids          {self.void_pct:.3f} % of covered pixels (mask: {self.void_mask_path})",
            (f"height range   h {self.h_min_m:.1f} .. {self.h_max_m:.1f} m (WGS84 ellipsoid), "
             f"H {self.H_min_m:.1f} .. {self.H_max_m:.1f} m (EGM96)"),
        ]


# ---- per-tile functions: slice, call core, return arrays -------------------------------------


def ellipsoidal_block(H: np.ndarray, lon: np.ndarray, lat: np.ndarray, geoid: GeoidGrid) -> np.ndarray:
    """h = H + N(lon, lat) on one block; NaN voids stay NaN."""
    return geoid.orthometric_to_ellipsoidal(lon, lat, H).astype(np.float32)


def void_block(
    H: np.ndarray, lon: np.ndarray, lat: np.ndarray, tiles: tuple[SrtmTile, ...]
) -> np.ndarray:
    """0 valid, 1 SRTM void, 2 no tile, on one block."""
    inside = covered(lon, lat, list(tiles))
    out = np.where(np.isnan(H), VOID_SRTM, VOID_VALID).astype(np.uint8)
    out[np.broadcast_to(~inside, out.shape)] = VOID_UNCOVERED
    return out


# ---- tasks -------------------------------------------------------------------------------------


@task(name="locate-srtm-tiles")
def locate_tiles(srtm_dir: Path, bbox: BBox, allow_missing: bool = False) -> list[SrtmTile]:
    """Find and check the SRTM tiles covering the box (EGM96 heights, as SRTM is: the one
    vertical-datum rule of :func:`tasks.io.dem.dem_datum` on each)."""
    tiles = find_tiles(srtm_dir, bbox, allow_missing=allow_missing)
    check_srtm_tiles(tiles)
    return tiles


def open_mosaic(tiles: list[SrtmTile], bbox: BBox, vrt_path: Path) -> xr.DataArray:
    """Lazy orthometric mosaic (float32, NaN voids) over the box, chunked ~1024x1024."""
    grid = mosaic_grid(tiles, bbox)
    vrt_path.write_text(build_vrt(tiles, grid))
    H = rioxarray.open_rasterio(vrt_path, chunks={"x": CHUNK, "y": CHUNK}, masked=True)
    return H.squeeze("band", drop=True)


@task(name="build-ellipsoidal-reference")
def build_reference(
    tiles: list[SrtmTile], bbox: BBox, out: Path, geoid_path: Path | None = None
) -> ReferenceSummary:
    """Mosaic the tiles, convert H to h = H + N block by block, write COG + void mask + JSON."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    geoid = load_geoid(str(geoid_path) if geoid_path else None)
    mask_path = out.with_name(out.stem + ".voids.tif")
    with tempfile.TemporaryDirectory(dir=out.parent, prefix=f".{out.name}.vrt") as tmp:
        H = open_mosaic(tiles, bbox, Path(tmp) / "mosaic.vrt")
        h = xr.apply_ufunc(
            ellipsoidal_block, H, H.x, H.y, kwargs={"geoid": geoid},
            dask="parallelized", output_dtypes=[np.float32],
        )
        h = h.rio.write_crs("EPSG:4326").rio.write_nodata(np.nan, encoded=False)
        h.attrs = {
            "long_name": "ellipsoidal height",
            "units": "m",
            "vertical_datum": "WGS84 ellipsoid (h = SRTM H + EGM96 N)",
        }
        voids = xr.apply_ufunc(
            void_block, H, H.x, H.y, kwargs={"tiles": tuple(tiles)},
            dask="parallelized", output_dtypes=[np.uint8],
        )
        voids = voids.rio.write_crs("EPSG:4326").rio.write_nodata(255)
        voids.attrs = {"long_name": "0 valid, 1 SRTM void, 2 no SRTM tile"}

        counts = [(voids.data == v).sum() for v in (VOID_VALID, VOID_SRTM, VOID_UNCOVERED)]
        # one pass over the mosaic: both COGs and the summary statistics; a block with no
        # SRTM at all has a NaN minimum and maximum, which the reduction then skips
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", "All-NaN slice encountered", RuntimeWarning)
            n_valid, n_void, n_unc, hmin, hmax, Hmin, Hmax = write_arrays_cog(
                [cog_item(voids, mask_path, resampling="nearest"), cog_item(h, out)],
                extra=[*counts, darr.nanmin(h.data), darr.nanmax(h.data),
                       darr.nanmin(H.data), darr.nanmax(H.data)],
            )
    n_cov = int(n_valid) + int(n_void)
    total = n_cov + int(n_unc)
    summary = ReferenceSummary(
        path=str(out),
        void_mask_path=str(mask_path),
        bbox=(bbox.lon_min, bbox.lat_min, bbox.lon_max, bbox.lat_max),
        width=int(H.sizes["x"]),
        height=int(H.sizes["y"]),
        res_arcsec=round(abs(float(H.rio.resolution()[0])) / ARCSEC, 6),
        tiles=tuple(t.path.name for t in tiles),
        coverage_pct=100.0 * n_cov / total,
        void_pct=100.0 * int(n_void) / max(n_cov, 1),
        h_min_m=float(hmin), h_max_m=float(hmax), H_min_m=float(Hmin), H_max_m=float(Hmax),
    )
    atomic_write_text(out.with_suffix(".json"), summary.to_json())
    return summary


@task(name="render-hillshade")
def render_hillshade(dem_path: Path, png_path: Path, max_px: int = 1600) -> Path:
    """A shaded-relief PNG of a DEM, read from a COG overview so memory stays small."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import rasterio
    from matplotlib.colors import LightSource
    from rasterio.enums import Resampling

    with rasterio.open(dem_path) as src:
        f = max(1, int(np.ceil(max(src.width, src.height) / max_px)))
        shape = (max(2, src.height // f), max(2, src.width // f))
        z = src.read(1, out_shape=shape, resampling=Resampling.average, masked=True)
        b = src.bounds
    m_lon, m_lat = metres_per_degree(0.5 * (b.top + b.bottom))
    dy = float((b.top - b.bottom) / shape[0] * m_lat)
    dx = float((b.right - b.left) / shape[1] * m_lon)
    zf = z.filled(np.nan).astype(np.float64)
    fill = np.where(np.isnan(zf), np.nanmean(zf), zf)
    ls = LightSource(azdeg=315, altdeg=45)
    rgb = ls.shade(fill, cmap=plt.get_cmap("gist_earth"), blend_mode="soft", dx=dx, dy=dy,
                   vert_exag=1.0, vmin=np.nanmin(zf), vmax=np.nanmax(zf))
    rgb[np.isnan(zf)] = (1.0, 0.0, 1.0, 1.0)
    fig, ax = plt.subplots(figsize=(8, 8 * shape[0] / shape[1] + 0.6), dpi=120)
    ax.imshow(rgb, extent=(b.left, b.right, b.bottom, b.top))
    ax.set_xlabel("longitude (deg)")
    ax.set_ylabel("latitude (deg)")
    ax.set_title(f"{Path(dem_path).name}: ellipsoidal heights {np.nanmin(zf):.0f}..{np.nanmax(zf):.0f} m")
    buf = io.BytesIO()
    try:
        fig.savefig(buf, format="png", bbox_inches="tight")
    finally:
        plt.close(fig)
    atomic_write_bytes(png_path, buf.getvalue())
    return Path(png_path)

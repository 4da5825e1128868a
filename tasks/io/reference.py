"""Tasks of the reference preparation: DEM tiles (SRTM, NASADEM, Copernicus, tagged DEMs) + their
geoid -> ellipsoidal reference DEM (COG), void mask, summary."""

from __future__ import annotations

import io
import tempfile
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import dask.array as darr
import numpy as np
import rioxarray
import xarray as xr
from prefect import task

from core.geodesy import ARCSEC, BBox, metres_per_degree
from core.geoid import GeoidGrid
from core.heights import DatumDecision
from core.jsonio import to_json
from tasks.io.dem import tile_datum
from tasks.io.dem_tiles import (
    DemSource,
    DemTile,
    TileSet,
    build_mask_vrt,
    build_vrt,
    covered,
    find_tiles,
    mosaic_grid,
)
from tasks.io.geoid import load_geoid, read_geoid
from tasks.io.rasters import (
    CHUNK,
    atomic_write_bytes,
    atomic_write_text,
    cog_item,
    write_arrays_cog,
)

#: the void mask's codes: valid, a void of the DEM itself, no tile, the product's water mask,
#: the product's height error above the limit
VOID_VALID, VOID_SRTM, VOID_UNCOVERED, VOID_WATER, VOID_HEIGHT_ERROR = 0, 1, 2, 3, 4
VOID_LEGEND = "0 valid, 1 DEM void, 2 no tile, 3 water (product mask), 4 height error > limit"


@dataclass(frozen=True)
class ReferenceSummary:
    """What ``prepare_reference`` produced and what it found. ``res_arcsec`` is the spacing
    along longitude, ``res_lat_arcsec`` along latitude; ``heights`` the tiles' datum decision
    (``vertical``, ``vertical_source``, and the ``geoid`` grid their heights went through when
    not the bundled EGM96)."""

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
    product: str = "SRTM"
    res_lat_arcsec: float | None = None
    heights: dict[str, str] = field(default_factory=dict)
    water_pct: float = 0.0
    height_error_pct: float = 0.0
    max_height_error_m: float | None = None

    def to_json(self) -> str:
        return to_json(asdict(self), indent=2)

    def lines(self) -> list[str]:
        lat = self.res_arcsec if self.res_lat_arcsec is None else self.res_lat_arcsec
        cells = (f"{self.res_arcsec:g} arcsec" if lat == self.res_arcsec
                 else f"{self.res_arcsec:g}\" x {lat:g}\" (lon x lat)")
        out = [
            f"reference DEM  {self.path}",
            (f"grid           {self.width} x {self.height} px at {cells}, "
             f"{len(self.tiles)} {self.product} tile(s): {', '.join(self.tiles)}"),
            f"coverage       {self.coverage_pct:.2f} % of the box has {self.product} tiles",
            f"voids          {self.void_pct:.3f} % of covered pixels (mask: {self.void_mask_path})",
        ]
        if self.water_pct or self.height_error_pct:
            out.append(f"masked         {self.water_pct:.3f} % water, {self.height_error_pct:.3f} % "
                       f"height error > {self.max_height_error_m:g} m (the product's own masks)")
        geoid = DatumDecision(**_decision_args(self.heights)).geoid_label if self.heights else "EGM96"
        out.append(f"height range   h {self.h_min_m:.1f} .. {self.h_max_m:.1f} m (WGS84 ellipsoid), "
                   f"H {self.H_min_m:.1f} .. {self.H_max_m:.1f} m ({geoid or 'ellipsoidal tiles: H is h'})")
        return out


def _decision_args(d: dict[str, str]) -> dict[str, Any]:
    return {"datum": d["vertical"], "source": d["vertical_source"], "geoid": d.get("geoid"),
            "geoid_source": d.get("geoid_source")}


# ---- per-tile functions: slice, call core, return arrays -------------------------------------


def ellipsoidal_block(H: np.ndarray, lon: np.ndarray, lat: np.ndarray, code: np.ndarray,
                      geoid: GeoidGrid | None) -> np.ndarray:
    """h = H + N(lon, lat) on one block (H itself for ellipsoidal tiles: ``geoid`` None) where
    the void mask says valid; NaN elsewhere."""
    h = H if geoid is None else geoid.orthometric_to_ellipsoidal(lon, lat, H)
    return np.where(code == VOID_VALID, h, np.nan).astype(np.float32)


def void_block(H: np.ndarray, lon: np.ndarray, lat: np.ndarray, *masks: np.ndarray,
               kinds: tuple[str, ...], tiles: tuple[DemTile, ...],
               max_height_error_m: float) -> np.ndarray:
    """The void mask's code on one block: no tile, else a DEM void (NaN, or the product's
    editing mask saying void), else water (the product's water-body mask: ocean, lake, river),
    else a height error (the product's mask, 1 sigma) above ``max_height_error_m``."""
    out = np.full(H.shape, VOID_VALID, dtype=np.uint8)
    by_kind = dict(zip(kinds, masks, strict=True))
    if "HEM" in by_kind:
        with np.errstate(invalid="ignore"):
            out[by_kind["HEM"] > max_height_error_m] = VOID_HEIGHT_ERROR
    if "WBM" in by_kind:
        out[(by_kind["WBM"] >= 1) & (by_kind["WBM"] <= 3)] = VOID_WATER
    void = np.isnan(H)
    if "EDM" in by_kind:
        void |= by_kind["EDM"] == 0
    out[void] = VOID_SRTM
    out[np.broadcast_to(~covered(lon, lat, list(tiles)), out.shape)] = VOID_UNCOVERED
    return out


# ---- tasks -------------------------------------------------------------------------------------


@task(name="locate-dem-tiles")
def locate_tiles(source: DemSource | Path, bbox: BBox, allow_missing: bool = False,
                 option: str = "--reference-vertical") -> TileSet:
    """Find and check the DEM tiles covering the box (a folder of SRTM, NASADEM or Copernicus
    tiles, or of tagged DEMs, or one DEM file: :func:`tasks.io.dem_tiles.find_tiles`) and
    decide their heights' datum and geoid by the one rule (:func:`tasks.io.dem.tile_datum`)."""
    return tile_datum(find_tiles(source, bbox, allow_missing=allow_missing), option)


def _lazy(vrt_path: Path, text: str) -> xr.DataArray:
    vrt_path.write_text(text)
    da = rioxarray.open_rasterio(vrt_path, chunks={"x": CHUNK, "y": CHUNK}, masked=True)
    return da.squeeze("band", drop=True)


def open_mosaic(tiles: TileSet, bbox: BBox, vrt_path: Path) -> xr.DataArray:
    """Lazy orthometric mosaic (float32, NaN voids) over the box, chunked ~1024x1024."""
    return _lazy(vrt_path, build_vrt(tiles, mosaic_grid(tiles, bbox)))


def open_masks(tiles: TileSet, bbox: BBox, folder: Path) -> dict[str, xr.DataArray]:
    """The product's own masks of the tiles (``WBM``, ``HEM``, ``EDM`` of Copernicus DEM's
    AUXFILES, those found beside the tiles) on the mosaic's grid, lazily, by kind."""
    grid = mosaic_grid(tiles, bbox)
    out = {}
    for kind in ("WBM", "HEM", "EDM"):
        text = build_mask_vrt(tiles, grid, kind)
        if text is not None:
            out[kind] = _lazy(folder / f"{kind}.vrt", text)
    return out


def reference_geoid(datum: DatumDecision, bbox: BBox) -> GeoidGrid | None:
    """The geoid grid the decided heights go through over the box: None for ellipsoidal
    heights, the bundled EGM96 unless the decision names another grid."""
    if not datum.orthometric:
        return None
    if datum.geoid is None:
        return load_geoid()
    return read_geoid(datum.geoid, bbox)


def heights_tag(tiles: TileSet) -> str:
    """The ``vertical_datum`` tag of the reference made from ``tiles``: ellipsoidal, and the
    product and geoid its heights came through (``WGS84 ellipsoid (h = SRTM H + EGM96 N)``)."""
    d = tiles.datum
    if d is None or not d.orthometric:
        return f"WGS84 ellipsoid ({tiles.product.name} heights as they are)"
    if d.geoid is None:
        return f"WGS84 ellipsoid (h = {tiles.product.name} H + {d.geoid_label} N)"
    return f"WGS84 ellipsoid (h = {tiles.product.name} H + N, {d.geoid_label})"


@task(name="build-ellipsoidal-reference")
def build_reference(tiles: TileSet, bbox: BBox, out: Path) -> ReferenceSummary:
    """Mosaic the tiles, void what the product's masks say, convert H to h = H + N through
    the geoid the tiles' datum decision names, block by block; write COG + void mask + JSON."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tiles = tiles if tiles.datum is not None else tile_datum(tiles)
    geoid = reference_geoid(tiles.datum, bbox)  # type: ignore[arg-type]
    mask_path = out.with_name(out.stem + ".voids.tif")
    limit = tiles.source.max_height_error_m
    with tempfile.TemporaryDirectory(dir=out.parent, prefix=f".{out.name}.vrt") as tmp:
        H = open_mosaic(tiles, bbox, Path(tmp) / "mosaic.vrt")
        masks = open_masks(tiles, bbox, Path(tmp))
        voids = xr.apply_ufunc(
            void_block, H, H.x, H.y, *masks.values(),
            kwargs={"kinds": tuple(masks), "tiles": tiles.tiles, "max_height_error_m": limit},
            dask="parallelized", output_dtypes=[np.uint8],
        )
        h = xr.apply_ufunc(
            ellipsoidal_block, H, H.x, H.y, voids, kwargs={"geoid": geoid},
            dask="parallelized", output_dtypes=[np.float32],
        )
        h = h.rio.write_crs("EPSG:4326").rio.write_nodata(np.nan, encoded=False)
        h.attrs = {"long_name": "ellipsoidal height", "units": "m",
                   "vertical_datum": heights_tag(tiles)}
        voids = voids.rio.write_crs("EPSG:4326").rio.write_nodata(255)
        voids.attrs = {"long_name": VOID_LEGEND}
        kept = H.where(voids == VOID_VALID)
        codes = (VOID_VALID, VOID_SRTM, VOID_UNCOVERED, VOID_WATER, VOID_HEIGHT_ERROR)
        counts = [(voids.data == v).sum() for v in codes]
        # one pass over the mosaic: both COGs and the summary statistics; a block with no
        # tile at all has a NaN minimum and maximum, which the reduction then skips
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", "All-NaN slice encountered", RuntimeWarning)
            *n, hmin, hmax, Hmin, Hmax = write_arrays_cog(
                [cog_item(voids, mask_path, resampling="nearest"), cog_item(h, out)],
                extra=[*counts, darr.nanmin(h.data), darr.nanmax(h.data),
                       darr.nanmin(kept.data), darr.nanmax(kept.data)],
            )
    n_valid, n_void, n_unc, n_water, n_err = (int(v) for v in n)
    n_cov = n_valid + n_void + n_water + n_err
    res = H.rio.resolution()
    summary = ReferenceSummary(
        path=str(out),
        void_mask_path=str(mask_path),
        bbox=(bbox.lon_min, bbox.lat_min, bbox.lon_max, bbox.lat_max),
        width=int(H.sizes["x"]),
        height=int(H.sizes["y"]),
        res_arcsec=round(abs(float(res[0])) / ARCSEC, 6),
        tiles=tiles.names,
        coverage_pct=100.0 * n_cov / (n_cov + n_unc),
        void_pct=100.0 * n_void / max(n_cov, 1),
        h_min_m=float(hmin), h_max_m=float(hmax), H_min_m=float(Hmin), H_max_m=float(Hmax),
        product=tiles.product.name,
        res_lat_arcsec=round(abs(float(res[1])) / ARCSEC, 6),
        heights=tiles.datum.to_dict(),  # type: ignore[union-attr]
        water_pct=100.0 * n_water / max(n_cov, 1),
        height_error_pct=100.0 * n_err / max(n_cov, 1),
        max_height_error_m=limit if "HEM" in masks else None,
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

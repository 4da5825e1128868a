"""STAC metadata for a run's raster products: one item per raster (with the projection
extension), all in a self-contained catalog ``OUT/stac/catalog.json``.

Items are built from the rasters themselves (footprint, bbox, EPSG, shape, transform), so the
catalog says what is on disk, not what was intended. Relative hrefs: the run folder can be
moved or published as it is.
"""

from __future__ import annotations

import datetime as dt
import itertools
import shutil
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pystac
import rasterio
from pystac.extensions.projection import ProjectionExtension
from rasterio.warp import transform_bounds, transform_geom

from core.errors import InputError
from tasks.io.rasters import atomic_write_json, read_json

MEDIA_COG = pystac.MediaType.COG


@dataclass(frozen=True)
class RasterProduct:
    """One raster to describe: ``key`` (item id suffix), ``path``, ``title`` and its STAC
    ``roles`` (``data``, ``metadata``...)."""

    key: str
    path: Path
    title: str
    roles: tuple[str, ...] = ("data",)


def _footprint(src: rasterio.io.DatasetReader) -> tuple[dict, list[float]]:
    """The raster's bounds as a WGS84 polygon (densified edges) and bbox."""
    if src.crs is None:
        raise InputError(f"{src.name} has no CRS: only georeferenced rasters get STAC items")
    left, bottom, right, top = src.bounds
    corners = [(left, bottom), (right, bottom), (right, top), (left, top), (left, bottom)]
    t = np.linspace(0.0, 1.0, 21)[:-1]  # 20 points an edge: projected edges are curves
    ring = [(x0 + (x1 - x0) * f, y0 + (y1 - y0) * f)
            for (x0, y0), (x1, y1) in itertools.pairwise(corners) for f in t]
    ring.append(ring[0])
    geom = transform_geom(src.crs, "EPSG:4326", {"type": "Polygon", "coordinates": [ring]},
                          antimeridian_cutting=True, precision=7)
    bbox = list(transform_bounds(src.crs, "EPSG:4326", *src.bounds, densify_pts=21))
    return geom, bbox


def raster_item(product: RasterProduct, item_id: str, when: dt.datetime,
                properties: Mapping[str, object] | None = None) -> pystac.Item:
    """A STAC item for one raster, with the projection extension filled from the file."""
    with rasterio.open(product.path) as src:
        geom, bbox = _footprint(src)
        epsg = src.crs.to_epsg()
        shape = [src.height, src.width]
        transform = list(src.transform)[:6]
        wkt = src.crs.to_wkt() if epsg is None else None
        tags = src.tags()
    item = pystac.Item(id=item_id, geometry=geom, bbox=bbox, datetime=when,
                       properties={"title": product.title, **(properties or {})})
    asset = pystac.Asset(href=str(product.path), media_type=MEDIA_COG, title=product.title,
                         roles=list(product.roles))
    vertical = tags.get("VERTICAL_DATUM") or tags.get("vertical_datum")
    if vertical:
        asset.extra_fields["gcpfree:vertical_datum"] = vertical
    item.add_asset(product.key, asset)
    proj = ProjectionExtension.ext(item, add_if_missing=True)
    proj.apply(epsg=epsg, wkt2=wkt, shape=shape, transform=transform, bbox=None)
    return item


def write_catalog(run_dir: str | Path, run_id: str, products: list[RasterProduct],
                  description: str, when: dt.datetime | None = None,
                  properties: Mapping[str, object] | None = None) -> Path:
    """Write ``run_dir/stac/catalog.json`` with one item per existing product, atomically
    (built in a temporary folder, then swapped in). Returns the catalog path."""
    run_dir = Path(run_dir)
    when = when or dt.datetime.now(dt.UTC)
    catalog = pystac.Catalog(id=run_id, description=description)
    for p in products:
        if p.path.exists():
            catalog.add_item(raster_item(p, f"{run_id}-{p.key}", when, properties))
    final = run_dir / "stac"
    tmp = Path(tempfile.mkdtemp(prefix="_stac_tmp_", dir=run_dir))
    try:
        catalog.normalize_hrefs(str(tmp) + "/")  # a folder, whatever its name
        # asset hrefs relative to each item's JSON, so the folder can move
        for item in catalog.get_items():
            for asset in item.assets.values():
                asset.href = str(Path(asset.href).resolve())
        catalog.make_all_asset_hrefs_relative()
        catalog.save(catalog_type=pystac.CatalogType.SELF_CONTAINED)
        old = run_dir / "_stac_old"
        if final.exists():
            shutil.rmtree(old, ignore_errors=True)
            final.rename(old)
        tmp.rename(final)
        shutil.rmtree(old, ignore_errors=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    # the hrefs were computed for the temporary folder at the same depth: still valid
    read_json(final / "catalog.json", "STAC catalog")
    return final / "catalog.json"


# ---------------------------------------------------------------------------- scenes


def footprint_item(item_id: str, ring_lonlat: list[tuple[float, float]],
                   when: dt.datetime | None, properties: Mapping[str, object] | None = None,
                   assets: Mapping[str, pystac.Asset] | None = None) -> pystac.Item:
    """A STAC item for a scene on the ground: its footprint polygon (lon, lat vertices,
    closed here) and bbox, its acquisition time (None when unknown: the item's
    ``start_datetime`` and ``end_datetime`` are then null too, as nothing states them)."""
    ring = [[float(lon), float(lat)] for lon, lat in ring_lonlat]
    if ring and ring[0] != ring[-1]:
        ring.append(ring[0])
    lons, lats = [p[0] for p in ring], [p[1] for p in ring]
    props = dict(properties or {})
    if when is None:
        props.update(start_datetime=None, end_datetime=None)
    item = pystac.Item(id=item_id, geometry={"type": "Polygon", "coordinates": [ring]},
                       bbox=[min(lons), min(lats), max(lons), max(lats)], datetime=when,
                       properties=props)
    for key, asset in (assets or {}).items():
        item.add_asset(key, asset)
    return item


def write_item_collection(items: list[pystac.Item], path: str | Path) -> Path:
    """``path``: a STAC ItemCollection (GeoJSON FeatureCollection) of ``items``, written
    atomically; asset hrefs as given (relative to ``path``'s folder for a movable folder)."""
    doc = pystac.ItemCollection(items, clone_items=False).to_dict(transform_hrefs=False)
    return atomic_write_json(Path(path), doc)

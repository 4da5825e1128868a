"""Every way of naming a model reaches the same model for the same raster (issue 17, item 1).

A user names an image's model four ways: found beside the image, ``--left-model``/``--model``
(:func:`load_model` with ``model=``), a catalog's ``left_model`` column (read by
:func:`tasks.archive.catalog.read_catalog`, loaded by :func:`tasks.relative.orientation.load_pair` as the flows
do), or the model file alone. For every family and format (OSSIM ``.geom``, DIMAP v2 RPC XML,
GeoTIFF RPC tags, SPOT ``.DIM``, gcpfree pushbroom, RPC and SAR ``.json``, a Sentinel-1
annotation found for a ``.SAFE`` measurement TIFF), on the uncropped raster
and on a crop carrying its pixel offset in its geotransform, the ways must agree; and the
crop's model must be the product's model moved by the crop offset, computed here from the
product's model read directly (the vendor reader, not :func:`load_model`), so a placement
error cannot cancel out.

The bug this pins: ``--left-model left_image.geom`` on the Ventoux crop skipped its (5000, 5000)
offset: the relative orientation then found -12.88 px across the epipolar lines instead of
-4.72 px.
"""

from __future__ import annotations

import csv
import json
import shutil
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import rasterio
from affine import Affine
from rasterio.errors import NotGeoreferencedWarning

from core.errors import InputError
from core.sensors.base import SensorModel
from core.sensors.linear_array import LookAngleTable
from core.sensors.pushbroom_synthetic import SyntheticSpec, synthetic_pushbroom
from core.sensors.rpc import RPCModel
from core.sensors.sentinel1 import parse_annotation
from core.sensors.spot import spot_pushbroom, spot_scene_from_model
from tasks.archive.catalog import read_catalog
from tasks.io.dimap import read_dimap, write_dimap
from tasks.io.sensors import load_model, rpc_from_dimap_file, rpc_from_geom_file
from tasks.relative.orientation import load_pair

DATA = Path(__file__).resolve().parents[1] / "data"
VENTOUX = DATA / "pleiades_ventoux"
DIMAP_V2 = DATA / "dimap" / "RPC_PHR1B_P_201308051042194_SEN_690908101-001.XML"
REUNION = DATA / "pleiades_reunion" / "img_01.tif"
S1_GRD = DATA / "sentinel1" / "s1b-iw-grd-vv-20210401t052623-20210401t052648-026269-032297-001.xml"
S1_SLC = DATA / "sentinel1" / "s1a-s3-slc-vh-20210401t152855-20210401t152914-037258-04638e-001.xml"


def _raster(path: Path, width: int, height: int, offset: tuple[float, float] | None = None,
            rpc_tags: dict[str, str] | None = None) -> Path:
    """A blank unreferenced raster (sparse: a product-sized one costs nothing), optionally a
    crop at ``offset`` (a pure pixel-offset geotransform) and with RPC tags."""
    kw = {"transform": Affine.translation(*offset)} if offset else {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        with rasterio.open(path, "w", driver="GTiff", width=width, height=height, count=1,
                           dtype="uint8", tiled=True, sparse_ok=True, **kw) as dst:
            if rpc_tags:
                dst.update_tags(ns="RPC", **rpc_tags)
    return path


@dataclass(frozen=True)
class Case:
    """A model file, the product model it holds (read by the vendor reader), and where a
    raster of it is named beside: ``beside(folder, stem)`` -> (image path, model path)."""

    name: str
    product: SensorModel
    product_size: tuple[int, int]
    model_file: Path
    beside: Callable[[Path, str], tuple[str, str]]
    probe_h: float
    crop_offset: tuple[float, float] = (37.0, 21.0)
    crop_size: tuple[int, int] = (200, 150)


def _same_stem(suffix: str) -> Callable[[Path, str], tuple[str, str]]:
    return lambda _d, stem: (f"{stem}.tif", f"{stem}{suffix}")


@pytest.fixture(scope="module")
def cases(tmp_path_factory) -> dict[str, Case]:
    d = tmp_path_factory.mktemp("models")
    geom = rpc_from_geom_file(VENTOUX / "left_image.geom")
    full = (38416, 42220)  # the Ventoux product (its RPC's offsets are the image centre)
    spot = synthetic_pushbroom(SyntheticSpec(5.2, 44.2, n_cols=300, n_rows=200, gsd_m=20.0,
                                             incidence_deg=12.0,
                                             epoch_utc="2001-05-04T10:00:00Z"))
    scene = spot_scene_from_model(spot)
    write_dimap(scene, d / "METADATA.DIM")
    (d / "spot.json").write_text(spot.to_json())
    with rasterio.open(REUNION) as src:
        reunion = RPCModel.from_gdal_tags(src.tags(ns="RPC"))
        reunion_size = (src.width, src.height)
    (d / "rpc.json").write_text(json.dumps(reunion.to_dict()))
    grd = parse_annotation(S1_GRD.read_text(), S1_GRD.name).model
    # an adjusted SAR model written by gcpfree: its corrections travel with it
    slc = parse_annotation(S1_SLC.read_text(), S1_SLC.name).model.with_params([1.5e-3, 2e-8])
    (d / "sar.json").write_text(slc.to_json())
    return {
        "geom": Case("geom", geom, full, VENTOUX / "left_image.geom", _same_stem(".geom"),
                     500.0, (5037.0, 5021.0), (300, 300)),
        "dimap_v2": Case("dimap_v2", rpc_from_dimap_file(DIMAP_V2), full, DIMAP_V2,
                         lambda _d, _s: ("IMG_PHR1B_P_201308051042194_SEN_690908101-001_R1C1.tif",
                                         DIMAP_V2.name), 500.0, (5037.0, 5021.0), (300, 300)),
        "spot_dim": Case("spot_dim", spot_pushbroom(read_dimap(d / "METADATA.DIM")), (300, 200),
                         d / "METADATA.DIM", lambda _d, _s: ("IMAGERY.TIF", "METADATA.DIM"),
                         300.0),
        "pushbroom_json": Case("pushbroom_json", spot, (300, 200), d / "spot.json",
                               _same_stem(".json"), 300.0),
        "rpc_tags": Case("rpc_tags", reunion, reunion_size, REUNION,
                         lambda _d, stem: (f"{stem}.tif", f"{stem}.tif"), 1295.0),
        "rpc_json": Case("rpc_json", reunion, reunion_size, d / "rpc.json",
                         _same_stem(".json"), 1295.0),
        "sar_safe": Case("sar_safe", grd, (grd.n_cols, grd.n_rows), S1_GRD,
                         lambda _d, stem: (f"measurement/{stem}.tiff", f"annotation/{stem}.xml"),
                         200.0, (5037.0, 4021.0)),
        "sar_json": Case("sar_json", slc, (slc.n_cols, slc.n_rows), d / "sar.json",
                         _same_stem(".json"), 200.0, (1037.0, 2021.0)),
    }


def _ground(case: Case) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ground points seen by 25 pixels spread over the crop (so inside the product too)."""
    (c0, r0), (w, h) = case.crop_offset, case.crop_size
    c, r = np.meshgrid(c0 + np.linspace(2.0, w - 3.0, 5), r0 + np.linspace(2.0, h - 3.0, 5))
    hh = np.full(c.size, case.probe_h)
    lon, lat = case.product.localize(c.ravel(), r.ravel(), hh)
    return lon, lat, hh


def _expected(case: Case, crop: tuple[float, float] | None, pts) -> np.ndarray:
    c, r = case.product.project(*pts)
    off = crop or (0.0, 0.0)
    return np.stack([c - off[0], r - off[1]])


def _catalog_models(folder: Path, image: Path, model: Path) -> SensorModel:
    cat = folder / "catalog.csv"
    with cat.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["id", "left", "right", "left_model", "right_model"])
        name = model.name if model.parent == folder else str(model)  # relative or absolute
        w.writerow(["p1", image.name, image.name, name, name])
    entry = read_catalog(cat).pairs[0]
    left, right = load_pair.fn(entry.pair_inputs())
    assert left.source == right.source == model
    return left.model


def _write_image(case: Case, folder: Path, stem: str, crop: tuple[float, float] | None
                 ) -> tuple[Path, Path]:
    """The raster (uncropped or the case's crop) and its model file placed beside it."""
    image_name, model_name = case.beside(folder, stem)
    image = folder / image_name
    image.parent.mkdir(parents=True, exist_ok=True)
    if case.name == "rpc_tags":
        # the product's own tags on the uncropped raster; a crop carries its tags re-normalised
        # as GDAL writes them when it crops
        own = case.product if crop is None else case.product.with_image_offset(*crop)
        size = case.product_size if crop is None else case.crop_size
        _raster(image, *size, offset=crop, rpc_tags=own.to_gdal_tags())
        return image, image
    size = case.product_size if crop is None else case.crop_size
    _raster(image, *size, offset=crop)
    model = folder / model_name
    model.parent.mkdir(parents=True, exist_ok=True)
    if case.name == "rpc_json" and crop is not None:
        # a gcpfree RPC .json is in the pixels of the raster it was written for (rel.json's
        # adjusted model of a crop): write the crop's
        model.write_text(json.dumps(case.product.with_image_offset(*crop).to_dict()))
    else:
        shutil.copy(case.model_file, model)
    return image, model


CASES = ["geom", "dimap_v2", "spot_dim", "pushbroom_json", "rpc_tags", "rpc_json", "sar_safe",
         "sar_json"]


@pytest.mark.parametrize("cropped", [False, True], ids=["uncropped", "cropped"])
@pytest.mark.parametrize("name", CASES)
def test_every_way_of_naming_a_model_gives_the_same_model(cases, tmp_path, name, cropped):
    case = cases[name]
    crop = case.crop_offset if cropped else None
    pts = _ground(case)
    want = _expected(case, crop, pts)
    tol = 1e-6 if isinstance(case.product, RPCModel) else 1e-4  # pushbroom, SAR: iterative

    image, model = _write_image(case, tmp_path / "beside", "img", crop)
    found = load_model(image)
    assert found.source == model and found.size == (
        case.product_size if crop is None else case.crop_size)
    ways = {"beside": found.model}
    # named on the command line: the model file elsewhere, under another name
    elsewhere = tmp_path / "models"
    elsewhere.mkdir()
    named_file = elsewhere / f"named{model.suffix}" if model != image else model
    if named_file != model:
        shutil.copy(model, named_file)
    other, other_model = _write_image(case, tmp_path / "plain", "plain", crop)
    if case.name == "rpc_tags":  # an image without its own tags, the model the tagged raster
        other.unlink()
        _raster(other, *(case.product_size if crop is None else case.crop_size), offset=crop)
        named_file = REUNION if crop is None else _product_tif(tmp_path, case)
    else:
        other_model.unlink()
    ways["named"] = load_model(other, model=named_file).model
    ways["catalog"] = _catalog_models(other.parent, other, named_file)
    if crop is None and model != image:
        ways["alone"] = load_model(named_file).model  # a model file given alone
    for way, m in ways.items():
        got = np.stack(m.project(*pts))
        np.testing.assert_allclose(got, want, atol=tol, err_msg=f"{name}: {way}")


def _product_tif(tmp_path: Path, case: Case) -> Path:
    """The product raster with its tags (identity geotransform): named as the model of a crop,
    its tags are moved by the crop's offset."""
    return _raster(tmp_path / "product.tif", *case.product_size,
                   rpc_tags=case.product.to_gdal_tags())


@pytest.mark.parametrize("name", CASES)
def test_a_model_file_alone_is_the_whole_product(cases, name):
    """Given alone, a file is the model of the image it describes, whatever crop it serves."""
    case = cases[name]
    alone = load_model(case.model_file)
    pts = _ground(case)
    np.testing.assert_allclose(np.stack(alone.model.project(*pts)), _expected(case, None, pts),
                               atol=1e-6 if isinstance(case.product, RPCModel) else 1e-4)
    if case.name != "rpc_tags":
        assert alone.image is None


def test_ventoux_named_and_found_models_agree():
    """The real crops: ``--left-model left_image.geom`` is the model found beside it."""
    for stem in ("left_image", "right_image"):
        found = load_model(VENTOUX / f"{stem}.tif")
        named = load_model(VENTOUX / f"{stem}.tif", model=VENTOUX / f"{stem}.geom")
        assert found.crop == named.crop != (0.0, 0.0)
        lon, lat = found.model.localize(np.array([0.0, 250.0, 499.0]),
                                        np.array([0.0, 250.0, 499.0]), 800.0)
        np.testing.assert_allclose(np.stack(named.model.project(lon, lat, 800.0)),
                                   [[0.0, 250.0, 499.0]] * 2, atol=1e-6)


def test_a_crop_outside_the_product_or_without_its_offset_is_refused(cases, tmp_path):
    case = cases["spot_dim"]
    inside = _raster(tmp_path / "crop.tif", 300, 300, offset=(37.0, 21.0))
    with pytest.raises(InputError, match="does not fit the 300x200 image"):
        load_model(inside, model=case.model_file)  # 300 rows from row 21 of 200
    bare = _raster(tmp_path / "bare.tif", 120, 80)
    with pytest.raises(InputError, match="not the same image.*pixel offset"):
        load_model(bare, model=case.model_file)
    # SPOT look angles are a table per detector: a crop starts on a whole detector
    assert isinstance(case.product.camera, LookAngleTable)
    half = _raster(tmp_path / "half.tif", 100, 100, offset=(10.5, 20.0))
    with pytest.raises(InputError, match="whole pixels"):
        load_model(half, model=case.model_file)

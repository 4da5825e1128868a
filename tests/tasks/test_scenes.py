"""``gcpfree scenes`` on a folder of synthetic SPOT-like scenes (gcpfree pushbroom models of known
geometry beside blank images), two real Pleiades crops and bad files: the stereo pairs and their
figures against independent checks (flat-Earth B/H of the stated incidences, footprint areas by
PROJ's geodesic and by counting points inside the polygons, the models' epochs), each pair
refused for its one reason and accepted when that threshold is lifted, blocks, every file
accounted for, and the catalog read back by the archive's reader."""

from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
import rasterio
from rasterio.errors import NotGeoreferencedWarning

from core.jsonio import to_json
from core.sensors.pushbroom_synthetic import SyntheticSpec, synthetic_pushbroom

DATA = Path(__file__).resolve().parents[1] / "data"
LON, LAT, N_PX, GSD_M = 5.25, 44.2, 600, 40.0
#: name -> (incidence deg, date, ascending, centre lon offset in px, bands)
SYNTHETIC = {
    "pass1/a25": (25.0, "2024-06-01", False, 0, 1),
    "pass2/b20": (-20.0, "2024-07-19", False, 0, 1),
    "c_east": (0.0, "2024-06-01", False, 540, 1),  # 90 % of a width east: overlaps ~10 %
    "d_ascending": (-20.0, "2024-06-01", True, 0, 1),
    "e_late": (-20.0, "2026-06-01", False, 0, 1),
    "f_ms": (-20.0, "2024-06-01", False, 0, 3),
    "far": (0.0, "2024-06-01", False, 6000, 1),
}


def blank_image(path: Path, n_px: int, bands: int = 1) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with warnings.catch_warnings():  # a raw sensor image has no CRS
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        with rasterio.open(path, "w", driver="GTiff", width=n_px, height=n_px, count=bands,
                           dtype="uint8", compress="deflate") as dst:
            dst.write(np.zeros((bands, n_px, n_px), np.uint8))


def synthetic_model(inc: float, date: str, ascending: bool, east_px: int):
    lon = LON
    if east_px:
        nadir = synthetic_pushbroom(SyntheticSpec(LON, LAT, n_cols=N_PX, n_rows=N_PX,
                                                  gsd_m=GSD_M))
        lon = float(nadir.localize(299.5 + east_px, 299.5, 0.0)[0])
    return synthetic_pushbroom(SyntheticSpec(lon, LAT, n_cols=N_PX, n_rows=N_PX, gsd_m=GSD_M,
                                             incidence_deg=inc, ascending=ascending,
                                             epoch_utc=f"{date}T10:00:00Z"))


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("scenes")
    for name, (inc, date, asc, east, bands) in SYNTHETIC.items():
        model = synthetic_model(inc, date, asc, east)
        blank_image(root / f"{name}.tif", N_PX, bands)
        (root / f"{name}.json").write_text(to_json(model.to_dict()))
    for name in ("img_01.tif", "img_02.tif"):  # a real RPC pair, its RPC in the tags
        (root / "pleiades").mkdir(exist_ok=True)
        (root / "pleiades" / name).symlink_to(DATA / "pleiades_reunion" / name)
    (root / "broken.tif").write_text("not a TIFF")
    blank_image(root / "nomodel.tif", 10)
    blank_image(root / "badmodel.tif", N_PX)
    (root / "badmodel.json").write_text('{"format": "gcpfree.pushbroom", "orbit": [1, 2')
    shutil.copy(DATA / "pleiades_gizeh" / "img1.geom", root / "lonely.geom")
    # not scenes: a simulated scene's truth/ and work/, a hidden folder
    (root / "sim" / "truth").mkdir(parents=True)
    (root / "sim" / "truth" / "scene.json").write_text("{}")
    blank_image(root / "sim" / "truth" / "dsm.tif", 10)
    blank_image(root / "sim" / "work" / "radiance_left.tif", 10)
    blank_image(root / ".hidden" / "x.tif", 10)
    (root / "pass1" / "again").symlink_to(root, target_is_directory=True)  # read once
    return root


def run_scenes(root: Path, out: Path, *options: str):
    from flows.cli import main

    assert main(["scenes", str(root), "--out", str(out), *options]) == 0
    return json.loads(out.read_text())


@pytest.fixture(scope="module")
def catalog(folder, tmp_path_factory):
    """The default run: (catalog path, its document)."""
    out = tmp_path_factory.mktemp("catalog") / "scenes.json"
    return out, run_scenes(folder, out)


def by_pair(doc: dict) -> dict[frozenset, dict]:
    return {frozenset((o["left"], o["right"])): o for o in doc["overlaps"]}


def test_the_stereo_pairs_are_the_two_that_meet_every_threshold(catalog):
    _, doc = catalog
    assert {p["id"] for p in doc["pairs"]} == {"b20__a25", "img_02__img_01"}
    pair = next(p for p in doc["pairs"] if p["id"] == "b20__a25")
    assert (pair["left_scene"], pair["right_scene"]) == ("b20", "a25")  # smaller incidence left
    assert pair["left"].endswith("pass2/b20.tif") and pair["left_model"].endswith("b20.json")


def test_pair_figures_against_independent_checks(catalog):
    """B/H of +25 / -20 deg across track is tan 25 + tan 20 within 0.01 (flat Earth); the
    date gap is the epochs' 48 days; the incidences are the stated ones."""
    _, doc = catalog
    f = next(p for p in doc["pairs"] if p["id"] == "b20__a25")["figures"]
    assert f["b_over_h"] == pytest.approx(np.tan(np.radians(25)) + np.tan(np.radians(20)),
                                          abs=0.01)
    assert f["convergence_deg"] == pytest.approx(45.0, abs=0.5)
    assert (f["incidence_left_deg"], f["incidence_right_deg"]) == pytest.approx((20, 25),
                                                                                abs=0.2)
    assert f["date_gap_days"] == pytest.approx(48.0, abs=0.01)
    assert f["heading_diff_deg"] < 10 and f["gsd_ratio"] < 1.3
    assert f["resolution"] == "spot-like" and f["b_over_h_range"] == [0.3, 1.2]


def _local(lon, lat, centre=None):
    """Metres of an azimuthal equidistant projection (PROJ) at ``centre`` (default: the first
    point): a plane without the distortion of a far UTM zone."""
    from pyproj import Transformer

    lon0, lat0 = centre or (float(np.ravel(lon)[0]), float(np.ravel(lat)[0]))
    t = Transformer.from_crs("EPSG:4326", f"+proj=aeqd +lon_0={lon0} +lat_0={lat0} +ellps=WGS84",
                             always_xy=True)
    return np.column_stack(t.transform(np.asarray(lon), np.asarray(lat)))


def test_footprint_areas_and_overlaps_measured_independently(catalog):
    """Each footprint's km2 against PROJ's geodesic polygon area; an overlap's km2 and share
    by counting the points of a fine grid inside both polygons (matplotlib's point-in-polygon,
    in UTM metres)."""
    from matplotlib.path import Path as Polygon
    from pyproj import Geod

    _, doc = catalog
    scenes = {s["id"]: s for s in doc["scenes"]}
    for s in scenes.values():
        lon, lat = np.array(s["footprint"]).T
        area, _ = Geod(ellps="WGS84").polygon_area_perimeter(lon, lat)
        assert s["area_km2"] == pytest.approx(abs(area) / 1e6, rel=2e-3)
    for ids in (("b20", "a25"), ("a25", "c_east"), ("img_02", "img_01")):
        centre = tuple(scenes[ids[0]]["footprint"][0])
        polys = [_local(*np.array(scenes[i]["footprint"]).T, centre) for i in ids]
        lo, hi = np.min(np.vstack(polys), axis=0), np.max(np.vstack(polys), axis=0)
        x, y = np.meshgrid(np.linspace(lo[0], hi[0], 600), np.linspace(lo[1], hi[1], 600))
        pts = np.column_stack([x.ravel(), y.ravel()])
        inside = [Polygon(p).contains_points(pts) for p in polys]
        cell = (hi[0] - lo[0]) / 599 * (hi[1] - lo[1]) / 599
        both = (inside[0] & inside[1]).sum() * cell / 1e6
        share = 100 * (inside[0] & inside[1]).sum() / min(inside[0].sum(), inside[1].sum())
        f = by_pair(doc)[frozenset(ids)]["figures"]
        assert f["overlap_km2"] == pytest.approx(both, rel=0.02)
        assert f["overlap_pct"] == pytest.approx(share, abs=1.0)


@pytest.mark.parametrize(("other", "reason", "option"), [
    ("c_east", "overlap", ["--min-overlap", "5"]),
    ("d_ascending", "headings differ", ["--max-heading-diff", "180"]),
    ("e_late", "days apart", ["--max-date-gap", "1000"]),
    ("f_ms", "band families differ", ["--any-band-family"]),
])
def test_each_refused_pair_has_its_one_reason_and_the_option_lifts_it(
        catalog, folder, tmp_path, other, reason, option):
    _, doc = catalog
    o = by_pair(doc)[frozenset(("a25", other))]
    assert not o["stereo"] and len(o["reasons"]) == 1 and reason in o["reasons"][0], o
    again = run_scenes(folder, tmp_path / "s.json", *option)
    assert by_pair(again)[frozenset(("a25", other))]["stereo"]


def test_heading_and_date_figures_of_the_refused_pairs(catalog):
    _, doc = catalog
    pairs = by_pair(doc)
    assert pairs[frozenset(("a25", "d_ascending"))]["figures"]["heading_diff_deg"] > 120
    assert pairs[frozenset(("a25", "e_late"))]["figures"]["date_gap_days"] == pytest.approx(
        730.0, abs=0.01)
    same_view = pairs[frozenset(("b20", "e_late"))]
    assert same_view["figures"]["b_over_h"] < 0.01 and "B/H" in same_view["reasons"][0]


def test_blocks_and_every_file_accounted_for(catalog, folder):
    """Two blocks (the synthetic scenes tied by their overlaps, the Pleiades pair); every
    image and lone model file of the folder is a scene or rejected with its reason, except
    the simulated scene's truth/ and work/ and the hidden folder."""
    _, doc = catalog
    blocks = {b["id"]: b for b in doc["blocks"]}
    assert blocks["block-1"]["scenes"] == ["a25", "b20", "c_east", "d_ascending", "e_late",
                                           "f_ms"]
    assert blocks["block-1"]["pairs"] == ["b20__a25"]
    assert blocks["block-2"] == {"id": "block-2", "scenes": ["img_01", "img_02"],
                                 "pairs": ["img_02__img_01"]}
    reasons = {Path(r["path"]).name: r["reason"] for r in doc["rejected"]}
    assert set(reasons) == {"far.tif", "broken.tif", "nomodel.tif", "badmodel.tif",
                            "lonely.geom"}
    assert "overlaps no other scene" in reasons["far.tif"]
    assert "cannot read image" in reasons["broken.tif"]
    assert "no sensor model found" in reasons["nomodel.tif"]
    assert "not valid JSON" in reasons["badmodel.tif"]
    assert "without its image" in reasons["lonely.geom"]
    listed = {Path(s["image"]).name for s in doc["scenes"]} | set(reasons)
    skipped = {"dsm.tif", "radiance_left.tif", "x.tif"}
    on_disk = {p.name for p in folder.rglob("*") if p.suffix in (".tif", ".geom")}
    assert listed == on_disk - skipped and not listed & skipped


def test_the_archive_reads_the_catalog(catalog):
    """The archive's reader: the pairs with their models (the same models the scenes were
    read with), the scenes, overlaps, blocks and rejected files."""
    from flows.reprocess_archive import pair_params
    from tasks.archive.catalog import read_catalog

    path, doc = catalog
    cat = read_catalog(path)
    assert cat.ids == tuple(p["id"] for p in doc["pairs"])
    assert [s.id for s in cat.scenes] == [s["id"] for s in doc["scenes"]]
    assert [b.pairs for b in cat.blocks] == [("b20__a25",), ("img_02__img_01",)]
    assert len(cat.overlaps) == len(doc["overlaps"]) and len(cat.rejected) == 5
    entry = cat.pairs[cat.ids.index("b20__a25")]
    params = pair_params(entry, path.parent / "root", None, DATA.parent.parent / "tasks" /
                         "data" / "N44E005.hgt")
    left, right = params.pair.load()
    centre = {s["id"]: s["centre"] for s in doc["scenes"]}["b20"]
    col, row = left.model.project(centre["lon_deg"], centre["lat_deg"], 0.0)
    assert (float(col), float(row)) == pytest.approx((299.5, 299.5), abs=1e-3)
    assert right.source.name == "a25.json" and params.out.name == "b20__a25"


def test_the_stac_item_collection_holds_each_scene_footprint(catalog):
    import pystac

    path, doc = catalog
    items = pystac.ItemCollection.from_file(str(path.with_name("scenes.stac.json")))
    assert [i.id for i in items] == [s["id"] for s in doc["scenes"]]
    for item, s in zip(items, doc["scenes"], strict=True):
        ring = item.geometry["coordinates"][0]
        assert ring[:4] == s["footprint"] and ring[4] == ring[0]
        assert (path.parent / item.assets["image"].href).resolve() == \
            (path.parent / s["image"]).resolve()
        assert item.properties["view:incidence_angle"] == pytest.approx(s["incidence_deg"])
    a25 = next(i for i in items if i.id == "a25")
    assert a25.datetime is not None and a25.datetime.date().isoformat() == "2024-06-01"


def test_a_flat_reference_sets_every_height(folder, tmp_path):
    """A reference DEM 800 m above the ellipsoid everywhere: every scene's footprint at 800 m
    (the synthetic scenes' own height is 0), the oblique one's moved by about 800 tan(25)."""
    ref = tmp_path / "flat.tif"
    with rasterio.open(ref, "w", driver="GTiff", width=200, height=200, count=1,
                       dtype="float32", crs="EPSG:4326",
                       transform=rasterio.transform.from_origin(4.0, 45.5, 0.02, 0.02)) as d:
        d.write(np.full((1, 200, 200), 800.0, np.float32))
        d.update_tags(vertical_datum="WGS84 ellipsoid")
    high = run_scenes(folder, tmp_path / "high.json", "--reference", str(ref))
    low = run_scenes(folder, tmp_path / "low.json")
    scenes = {s["id"]: s for s in high["scenes"]}
    assert scenes["a25"]["h_m"] == pytest.approx(800.0, abs=1e-3)
    assert "reference" in scenes["a25"]["height_source"]
    a_low = next(s for s in low["scenes"] if s["id"] == "a25")
    moved = _local(*np.array(scenes["a25"]["footprint"]).T, (LON, LAT)) - \
        _local(*np.array(a_low["footprint"]).T, (LON, LAT))
    assert np.hypot(*moved.T).mean() == pytest.approx(800 * np.tan(np.radians(25)), rel=0.1)
    # the Pleiades crops are off the reference: rejected with its reason
    assert any("does not cover" in r["reason"] for r in high["rejected"]
               if Path(r["path"]).name == "img_01.tif")


def test_dem_tiles_give_the_heights_where_they_cover(folder, tmp_path):
    """The bundled SRTM tile as --dem-dir: the synthetic scenes' heights are SRTM's (EGM96
    converted) under them, within the tile's range; the Reunion crops are off the tiles."""
    from tasks.io.geoid import BUNDLED_SRTM_DIR

    doc = run_scenes(folder, tmp_path / "dem.json", "--dem-dir", str(BUNDLED_SRTM_DIR))
    with rasterio.open(BUNDLED_SRTM_DIR / "N44E005.hgt") as src:
        H = src.read(1)
    a25 = next(s for s in doc["scenes"] if s["id"] == "a25")
    assert H.min() + 40 < a25["h_m"] < H.max() + 60  # h = H + N, N about +50 m here
    assert "SRTM tiles' mean height" in a25["height_source"] and "SRTM" in doc["heights"]
    off = {Path(r["path"]).name: r["reason"] for r in doc["rejected"]}
    assert "missing tile(s) S22E055" in off["img_01.tif"]


@pytest.mark.parametrize(("change", "fragment"), [
    (lambda d: d["blocks"][0]["scenes"].append("nowhere"), "names scene nowhere"),
    (lambda d: d["pairs"][0].update(left_scene="nowhere"), "names scene nowhere"),
    (lambda d: d.update(version=2), "version 2"),
    (lambda d: d["pairs"][0].update(colour="red"), r"unknown column\(s\) colour"),
])
def test_the_reader_refuses_a_damaged_scenes_catalog(catalog, tmp_path, change, fragment):
    from core.errors import InputError
    from tasks.archive.catalog import read_catalog

    _, doc = catalog
    damaged = json.loads(json.dumps(doc))
    change(damaged)
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(damaged))
    with pytest.raises(InputError, match=fragment):
        read_catalog(bad)

"""``gcpfree scenes`` on real and simulated folders: the simulator's tiny pair (its truth/ and
work/ not scenes, its pair's B/H and date gap against the metadata it wrote, heights from its
reference and from SRTM agreeing, the archive's parameters for the proposed pair), the real
Pleiades triplet (three pairs in one block at the B/H its data README states) and real SPOT
DIMAP metadata (read with their satellites, dates and angles; two places that overlap nothing,
and a metadata file without its image). The last two need ../shared and skip without it."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import rasterio

from tasks.io.geoid import BUNDLED_SRTM_DIR

REPO = Path(__file__).resolve().parents[2]
SHARED = REPO.parent / "shared" / "data"
TRIPLET = SHARED / "pleiades_marseille_triplet"
SPOT_DIMAP = SHARED / "spot_dimap"


def run_scenes(folder: Path, out: Path, *options: str) -> dict:
    from flows.cli import main

    assert main(["scenes", str(folder), "--out", str(out), *options]) == 0
    return json.loads(out.read_text())


@pytest.fixture(scope="module")
def tiny_catalog(tiny_scene, tmp_path_factory):
    """The tiny scene's folder with its own reference: (scene folder, catalog path, doc)."""
    scene, _ = tiny_scene
    out = tmp_path_factory.mktemp("tiny_scenes") / "scenes.json"
    return scene, out, run_scenes(scene, out, "--reference", str(scene / "reference.tif"))


def test_the_simulated_pair_is_found_with_the_metadata_figures(tiny_catalog):
    """One stereo pair of the two images (the -20 deg one left), B/H the flat-Earth
    tan 25.5 + tan 20 of the incidences the .DIM files state, the 48 days between their
    dates; truth/ and work/ are no scenes, the reference DEM is rejected as having no model."""
    from tasks.io.dimap import read_dimap

    scene, _, doc = tiny_catalog
    assert [s["id"] for s in doc["scenes"]] == ["left", "right"]
    assert [p["id"] for p in doc["pairs"]] == ["right__left"]
    stated = {side: read_dimap(scene / f"{side}.DIM") for side in ("left", "right")}
    f = doc["pairs"][0]["figures"]
    want = sum(np.tan(np.radians(abs(s.incidence_deg))) for s in stated.values())
    assert f["b_over_h"] == pytest.approx(want, abs=0.01)
    days = (np.datetime64(stated["right"].epoch_utc.rstrip("Z"))
            - np.datetime64(stated["left"].epoch_utc.rstrip("Z"))) / np.timedelta64(1, "D")
    assert f["date_gap_days"] == pytest.approx(days, abs=0.01) and days == 48
    assert [Path(r["path"]).name for r in doc["rejected"]] == ["reference.tif"]
    assert "no sensor model" in doc["rejected"][0]["reason"]
    assert doc["blocks"] == [{"id": "block-1", "scenes": ["left", "right"],
                              "pairs": ["right__left"]}]


def test_reference_and_srtm_heights_agree_and_lie_within_the_truth(tiny_catalog, tmp_path):
    scene, _, doc = tiny_catalog
    srtm = run_scenes(scene, tmp_path / "srtm.json", "--srtm-dir", str(BUNDLED_SRTM_DIR))
    with rasterio.open(scene / "truth" / "dsm.tif") as src:
        truth = src.read(1, masked=True)
    for ref, s in zip(doc["scenes"], srtm["scenes"], strict=True):
        assert float(truth.min()) < ref["h_m"] < float(truth.max())
        assert s["h_m"] == pytest.approx(ref["h_m"], abs=15.0)
        assert "SRTM" in s["height_source"] and "reference" in ref["height_source"]


def test_the_archive_runs_the_proposed_pair_with_its_models(tiny_catalog):
    from flows.reprocess_archive import pair_params
    from tasks.archive.catalog import read_catalog

    scene, out, _ = tiny_catalog
    cat = read_catalog(out)
    params = pair_params(cat.pairs[0], out.parent / "root", None, scene / "reference.tif")
    assert (params.pair.left, params.pair.right) == (scene / "right.tif", scene / "left.tif")
    assert (params.pair.left_model, params.pair.right_model) == (scene / "right.DIM",
                                                                 scene / "left.DIM")
    assert params.out == out.parent / "root" / "right__left"


@pytest.mark.skipif(not TRIPLET.is_dir(), reason="needs ../shared/data/pleiades_marseille_triplet")
def test_the_pleiades_triplet_is_three_pairs_in_one_block(tmp_path):
    """B/H 0.11 and 0.23 between the pairs, as the data's README states."""
    doc = run_scenes(TRIPLET, tmp_path / "triplet.json")
    bh = {p["id"]: p["figures"]["b_over_h"] for p in doc["pairs"]}
    assert set(bh) == {"img_02__img_01", "img_02__img_03", "img_01__img_03"}
    assert bh["img_02__img_01"] == pytest.approx(0.11, abs=0.006)
    assert bh["img_02__img_03"] == pytest.approx(0.11, abs=0.006)
    assert bh["img_01__img_03"] == pytest.approx(0.23, abs=0.006)
    assert [b["scenes"] for b in doc["blocks"]] == [["img_01", "img_02", "img_03"]]
    assert {s["acquired_utc"][:10] for s in doc["scenes"]} == {"2013-04-17"}
    assert all(p["figures"]["date_gap_days"] < 1 / 1440 for p in doc["pairs"])  # one pass


def _spot_folder(root: Path, name: str, dim: Path, n_px: int) -> None:
    """A SPOT Level 1A scene folder: the real METADATA.DIM beside an empty (sparse) image of
    its size."""
    folder = root / name
    folder.mkdir(parents=True)
    shutil.copy(dim, folder / "METADATA.DIM")
    with rasterio.open(folder / "IMAGERY.TIF", "w", driver="GTiff", width=n_px, height=n_px,
                       count=1, dtype="uint8", tiled=True, sparse_ok=True) as dst:
        dst.update_tags(note="no pixels: metadata test")


@pytest.mark.skipif(not SPOT_DIMAP.is_dir(), reason="needs ../shared/data/spot_dimap")
def test_real_spot_dimap_scenes(tmp_path):
    import warnings

    from rasterio.errors import NotGeoreferencedWarning

    from tasks.io.dimap import read_dimap

    root = tmp_path / "archive"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        _spot_folder(root, "spot2_scene", SPOT_DIMAP / "SPOT2.DIM", 6000)
        _spot_folder(root, "spot5_scene", SPOT_DIMAP / "SPOT5.DIM", 12000)
    (root / "lost").mkdir()
    shutil.copy(SPOT_DIMAP / "SPOT2.DIM", root / "lost" / "METADATA.DIM")
    from tasks.archive.scenes import GroundHeights, read_scenes

    scenes, rejected = read_scenes(root, GroundHeights())
    got = {s.id: s for s in scenes}
    assert set(got) == {"spot2_scene", "spot5_scene"}
    for sid, name, sat, inst, date, gsd in (
            ("spot2_scene", "SPOT2.DIM", "SPOT 2", "HRV 2", "1998-03-14", 10.0),
            ("spot5_scene", "SPOT5.DIM", "SPOT 5", "HRG 1", "2005-03-13", 5.0)):
        s, stated = got[sid], read_dimap(SPOT_DIMAP / name)
        assert (s.acquisition.satellite, s.acquisition.instrument) == (sat, inst)
        assert s.acquisition.utc[:10] == date
        assert s.incidence_deg == pytest.approx(abs(stated.incidence_deg), abs=0.3)
        assert s.gsd_m == pytest.approx(gsd, rel=0.05)
        assert s.sun_deg == (stated.sun_azimuth_deg, stated.sun_elevation_deg)
        assert s.band_family == "panchromatic" and s.area_km2 > 3000
    assert [r.path.parent.name for r in rejected] == ["lost"]
    assert "without its image" in rejected[0].reason
    # two places far apart: both rejected as overlapping nothing
    doc = run_scenes(root, tmp_path / "spot.json")
    assert doc["pairs"] == [] and doc["blocks"] == []
    lonely = [r for r in doc["rejected"] if "overlaps no other scene" in r["reason"]]
    assert {Path(r["path"]).parent.name for r in lonely} == {"spot2_scene", "spot5_scene"}

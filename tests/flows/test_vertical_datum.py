"""One vertical-datum rule for every command that reads a DEM (issue 17, item 2).

The same SRTM heights (the bundled N44E005 tile, EGM96) are written five ways a user meets
them: the ``.hgt`` itself, a GeoTIFF named after its tile (``N44E005.tif``), a GeoTIFF whose
``vertical_datum`` tag says EGM96, one with the compound CRS WGS 84 + EGM96 height, and the
same ground as WGS84 ellipsoidal heights ``h = H + N`` with a tag saying so; a sixth copy says
nothing of its datum. Every DEM-reading command must take the first five to the same
ellipsoidal heights, print the decision and write it into its JSON, and refuse the sixth in
one line naming its ``--*-vertical`` option. The registry of commands (``flows.cli.COMMANDS``)
is the list: a new command must say here whether it reads a DEM.

Before this rule four resolvers disagreed: the untagged lon/lat GeoTIFF was ellipsoidal to
``orient`` and EGM96 to ``fill-voids`` (about 50 m of height here).
"""

from __future__ import annotations

import argparse
import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import rasterio
from rasterio.crs import CRS
from rasterio.windows import Window

from tasks.io.geoid import BUNDLED_SRTM_DIR, load_geoid

DATA = Path(__file__).resolve().parents[1] / "data"
VENTOUX = DATA / "pleiades_ventoux"
HGT = BUNDLED_SRTM_DIR / "N44E005.hgt"
PAIR = ["--left", str(VENTOUX / "left_image.tif"), "--right", str(VENTOUX / "right_image.tif")]

#: the variants every command must read alike: (file name, tags, CRS, heights ellipsoidal)
VARIANTS = {
    "hgt": None,
    "srtm_named": ("N44E005.tif", {}, "EPSG:4326", False),
    "tagged": ("dem_tagged.tif", {"vertical_datum": "EGM96 geoid"}, "EPSG:4326", False),
    "compound": ("dem_compound.tif", {}, "EPSG:4326+5773", False),
    "ellipsoidal": ("dem_ellipsoidal.tif", {"vertical_datum": "WGS84 ellipsoid"}, "EPSG:4326",
                    True),
}
ACCEPTED = list(VARIANTS)
SOURCES = {"hgt": "SRTM file N44E005.hgt", "srtm_named": "SRTM file N44E005.tif",
           "tagged": "tag vertical_datum", "compound": "CRS: EGM96 height",
           "ellipsoidal": "tag vertical_datum"}


@pytest.fixture(scope="module")
def dems(tmp_path_factory) -> dict[str, Path]:
    """The six DEM files over lon 5.0-5.5, lat 44.0-44.45 (the Ventoux crops and the tiny
    scene), from the bundled tile."""
    d = tmp_path_factory.mktemp("datums")
    out = {"hgt": d / "N44E005.hgt"}
    shutil.copy(HGT, out["hgt"])
    with rasterio.open(HGT) as src:
        win = Window(0, int(round(0.55 * 1200)), 601, 541)
        H = src.read(1, window=win).astype(np.float64)
        tr = src.window_transform(win)
    H[H <= -1000] = np.nan
    rows, cols = np.mgrid[0:H.shape[0], 0:H.shape[1]]
    n_m = load_geoid().undulation_m(tr.c + (cols + 0.5) * tr.a, tr.f + (rows + 0.5) * tr.e)
    for name, spec in VARIANTS.items():
        if spec is None:
            continue
        fname, tags, crs, ellipsoidal = spec
        out[name] = d / fname
        _write(out[name], H + n_m if ellipsoidal else H, tr, crs, tags)
    out["untagged"] = d / "dem.tif"
    _write(out["untagged"], H, tr, "EPSG:4326", {})
    return out


def _write(path: Path, z: np.ndarray, tr, crs: str, tags: dict[str, str]) -> None:
    with rasterio.open(path, "w", driver="GTiff", width=z.shape[1], height=z.shape[0], count=1,
                       dtype="float32", crs=CRS.from_string(crs), transform=tr,
                       nodata=np.nan) as dst:
        dst.write(z.astype(np.float32), 1)
        if tags:
            dst.update_tags(**tags)


def _main(argv: list[str], capsys) -> tuple[int, str, str]:
    from flows.cli import main

    rc = main(argv)
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


# ----------------------------------------------------------------- every command, one rule

def _archive_catalog(folder: Path) -> Path:
    cat = folder / "catalog.csv"
    with cat.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["id", "left", "right"])
        w.writerow(["ventoux", VENTOUX / "left_image.tif", VENTOUX / "right_image.tif"])
    return cat


def _fake_orient_output(folder: Path) -> Path:
    out = folder / "orient_out"
    out.mkdir(exist_ok=True)
    (out / "report.json").write_text("{}")
    return out


#: each command that reads a DEM: its arguments with {dem} (and {dir} for outputs) and the
#: option that declares the datum. ``fill-voids`` reads two (the tile, then the DSM).
DEM_COMMANDS = {
    "info": (["info", str(VENTOUX / "left_image.tif"), "--reference", "{dem}"],
             "--reference-vertical"),
    "relative": (["relative", *PAIR, "--reference", "{dem}", "--out", "{dir}/rel.json"],
                 "--reference-vertical"),
    "dsm": (["dsm", *PAIR, "--reference", "{dem}", "--out", "{dir}/dsm.tif"],
            "--reference-vertical"),
    "orient": (["orient", *PAIR, "--reference", "{dem}", "--out", "{dir}/o"],
               "--reference-vertical"),
    "pair": (["pair", *PAIR, "--reference", "{dem}", "--out", "{dir}/p"],
             "--reference-vertical"),
    "archive": (["archive", "--catalog", "{catalog}", "--reference", "{dem}", "--out",
                 "{dir}/a"], "--reference-vertical"),
    "serve": (["serve", "--catalog", "{catalog}", "--reference", "{dem}", "--out", "{dir}/a",
               "--cron", "0 3 * * *"], "--reference-vertical"),
    "report": (["report", "{orient_out}", "--reference", "{dem}"], "--reference-vertical"),
    "ortho": (["ortho", "--image", str(VENTOUX / "left_image.tif"), "--dem", "{dem}", "--out",
               "{dir}/ortho.tif"], "--dem-vertical"),
    "evaluate": (["evaluate", "--dem", "{dem}", "--lidar", str(DATA / "lidar" /
                                                                "autzen_trim.laz"),
                  "--out", "{dir}/e.json"], "--dem-vertical"),
    "coregister": (["coregister", "--reference", "{dem}", "--dem", str(HGT), "--out",
                    "{dir}/c.json"], "--reference-vertical"),
    "fill-voids": (["fill-voids", "--srtm", "{dem}", "--dem", "{dem}", "--out",
                    "{dir}/filled.tif"], "--srtm-vertical"),
    "simulate": (["simulate", "--dem", "{dem}", "--out", "{dir}/scene"], "--dem-vertical"),
    "block": (["block", "--catalog", "{catalog}", "--reference", "{dem}", "--out", "{dir}/b"],
              "--reference-vertical"),
    # the mean terrain height under each scene's footprint, from --reference or --dem-dir
    "scenes": (["scenes", str(VENTOUX), "--reference", "{dem}", "--out", "{dir}/s.json"],
               "--reference-vertical"),
}
#: commands that read no DEM, and why
NO_DEM = {"ortho-compare": "compares two orthoimages",
          "prepare-reference": "reads SRTM tiles by name (tested below)",
          "project": "ellipsoidal heights given per point in the CSV, no DEM",
          "localize": "ellipsoidal heights given per point in the CSV, no DEM"}


def test_every_command_is_classified():
    from flows.cli import COMMANDS

    assert set(DEM_COMMANDS) | set(NO_DEM) == set(COMMANDS), (
        "a command was added: say in DEM_COMMANDS or NO_DEM whether it reads a DEM")


def _argv(name: str, dem: Path, folder: Path) -> list[str]:
    template, _ = DEM_COMMANDS[name]
    return [a.format(dem=dem, dir=folder, catalog=_archive_catalog(folder),
                     orient_out=_fake_orient_output(folder)) for a in template]


@pytest.mark.parametrize("name", sorted(DEM_COMMANDS))
def test_a_dem_whose_datum_cannot_be_told_is_refused_by_every_command(
        name, dems, tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("PREFECT_LOGGING_LEVEL", raising=False)
    monkeypatch.delenv("PREFECT_LOGGING_HANDLERS_CONSOLE_LEVEL", raising=False)
    argv = _argv(name, dems["untagged"], tmp_path)
    rc, _, err = _main(argv, capsys)
    option = DEM_COMMANDS[name][1]
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1, err
    assert "does not say whether its heights are ellipsoidal or EGM96" in lines[0], lines[0]
    assert f"give {option} egm96 or {option} ellipsoidal" in lines[0], lines[0]
    assert not any(p.name not in ("catalog.csv", "orient_out") for p in tmp_path.iterdir())


def test_prepare_reference_refuses_a_tile_whose_tag_says_ellipsoidal(dems, tmp_path, capsys):
    folder = tmp_path / "tiles"
    folder.mkdir()
    with rasterio.open(HGT) as src:  # the whole tile, SRTM-named, tagged ellipsoidal
        _write(folder / "N44E005.tif", src.read(1).astype(np.float64) + 50.0, src.transform,
               "EPSG:4326", {"vertical_datum": "WGS84 ellipsoid"})
    rc, _, err = _main(["prepare-reference", "--bbox", "5.1", "44.1", "5.2", "44.2",
                        "--srtm-dir", str(folder), "--out", str(tmp_path / "ref.tif")], capsys)
    assert rc == 2 and "holds ellipsoidal heights (tag vertical_datum=" in err
    assert not (tmp_path / "ref.tif").exists()


# ------------------------------------------- the same DEM five ways: one decision, one height

def _parsed(command: str, argv: list[str]) -> argparse.Namespace:
    from flows.cli import build_parser

    return build_parser().parse_args([command, *argv])


def _preflight_line(name: str, dem: Path, folder: Path, capsys) -> str:
    """The decision line a command prints before its run starts (its own pre-flight check)."""
    from flows.commands import archive, report
    from flows.commands._pair import check_pair

    args = _parsed(name, _argv(name, dem, folder)[1:])
    {"relative": check_pair, "dsm": check_pair, "orient": check_pair, "pair": check_pair,
     "archive": archive.check_archive_args, "report": report.check_inputs}[name](args)
    printed = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("reference")]
    assert len(printed) == 1, printed
    return printed[0]


@pytest.mark.parametrize("variant", ACCEPTED)
@pytest.mark.parametrize("name", ["relative", "dsm", "orient", "pair", "archive", "report"])
def test_the_long_commands_decide_alike_before_they_start(name, variant, dems, tmp_path,
                                                          capsys):
    line = _preflight_line(name, dems[variant], tmp_path, capsys)
    datum = "WGS84 ellipsoidal" if variant == "ellipsoidal" else "EGM96 orthometric"
    assert datum in line and SOURCES[variant] in line, line


def _info_height(dem: Path, folder: Path, capsys) -> dict:
    out = folder / f"info_{dem.stem}.json"
    rc, printed, err = _main(["info", str(VENTOUX / "left_image.tif"), "--reference", str(dem),
                              "--json", str(out)], capsys)
    assert rc == 0, err
    return json.loads(out.read_text())["reference"] | {"printed": printed}


def test_info_reads_the_same_heights_from_every_variant(dems, tmp_path, capsys):
    got = {v: _info_height(dems[v], tmp_path, capsys) for v in ACCEPTED}
    h = np.array([g["mean_h_m"] for g in got.values()])
    assert 400 < h[0] < 700 and np.ptp(h) < 0.05, h  # ~50 m apart if one datum were wrong
    for v, g in got.items():
        assert g["vertical"] == ("ellipsoidal" if v == "ellipsoidal" else "egm96")
        assert SOURCES[v] in g["vertical_source"] and SOURCES[v] in g["printed"]


@pytest.mark.parametrize("variant", ACCEPTED)
def test_coregister_compares_heights_in_one_datum(variant, dems, tmp_path, capsys):
    """Every variant against the ellipsoidal copy of the same ground: no shift, no ~50 m."""
    out = tmp_path / "c.json"
    rc, printed, err = _main(["coregister", "--reference", str(dems[variant]), "--dem",
                              str(dems["ellipsoidal"]), "--out", str(out)], capsys)
    assert rc == 0, err
    doc = json.loads(out.read_text())
    assert abs(doc["shift_up_m"]) < 0.05 and abs(doc["shift_east_m"]) < 0.5
    assert SOURCES[variant] in doc["reference_vertical"]["vertical_source"]
    assert SOURCES[variant] in printed


def test_ortho_is_the_same_over_every_variant(dems, tmp_path, capsys):
    arrays = {}
    for v in ("hgt", "compound", "ellipsoidal"):
        out = tmp_path / f"ortho_{v}.tif"
        rc, printed, err = _main(["ortho", "--image", str(VENTOUX / "left_image.tif"), "--dem",
                                  str(dems[v]), "--resolution", "2", "--out", str(out)], capsys)
        assert rc == 0, err
        assert SOURCES[v] in json.loads(out.with_suffix(".json").read_text())[
            "dem_vertical_source"] and SOURCES[v] in printed
        with rasterio.open(out) as src:
            arrays[v] = src.read(1).astype(np.float64)
    for v in ("compound", "ellipsoidal"):
        assert arrays[v].shape == arrays["hgt"].shape
        assert np.nanmax(np.abs(arrays[v] - arrays["hgt"])) <= 1.0  # 16-bit grey levels


def test_fill_voids_reads_every_variant_of_the_tile_alike(dems, tmp_path):
    from tasks.evaluation.void_fill import read_tile

    tiles = {v: read_tile(dems[v]) for v in ("hgt", "srtm_named", "tagged", "compound",
                                             "ellipsoidal")}
    for v, t in tiles.items():
        assert t.vertical == ("ellipsoidal" if v == "ellipsoidal" else "egm96")
        assert SOURCES[v] in t.vertical_source


def test_simulate_says_the_datum_of_its_dem(dems, tmp_path):
    from core.geodesy import BBox
    from tasks.simulate.io import read_dem_window

    box = BBox(5.2, 44.15, 5.3, 44.25)
    a, _, _ = read_dem_window(dems["hgt"], box, "egm96")
    b, _, _ = read_dem_window(dems["ellipsoidal"], box, "ellipsoidal")
    assert a.shape == b.shape and np.nanmax(np.abs(a - b)) < 0.01  # both orthometric H


def test_the_products_record_the_decision(tiny_oriented):
    """orient's report.json, its relative DEM and rel.json say which reference and datum."""
    _, out, outcome = tiny_oriented
    ref = outcome.report.reference
    assert ref.path.endswith("reference.tif") and ref.vertical == "ellipsoidal"
    assert ref.vertical_source.startswith("tag vertical_datum=")
    assert outcome.report.relative_dem.reference["vertical"] == "ellipsoidal"
    rel = json.loads((out / "relative" / "rel.json").read_text())
    assert rel["reference"]["path"] == ref.path
    assert rel["reference"]["vertical_source"] == ref.vertical_source
    assert outcome.report.surface_matching.settings["radius_m"] > 0

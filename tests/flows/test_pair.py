"""``gcpfree pair`` (flow ``pair``): the whole chain for one pair, resumed from the session's
orientation (which also proves the resume: the orientation step must be kept, not rerun),
evaluated against the simulated lidar, reported, catalogued in STAC, and checked by its
manifest."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pystac
import pytest
import rasterio
import rasterio.crs
from pystac.extensions.projection import ProjectionExtension
from rasterio.warp import transform_bounds

from flows.orient import OrientParams
from flows.pair import PairParams, manifest_defaults, pair_flow
from tasks.archive.pair import pair_complete
from tasks.io.pair import PairInputs


@pytest.fixture(scope="module")
def pair_run(tiny_oriented, tmp_path_factory):
    scene, oriented_out, _ = tiny_oriented
    out = tmp_path_factory.mktemp("pair") / "tiny-pair"
    shutil.copytree(oriented_out, out)
    params = PairParams(OrientParams(pair=PairInputs(scene / "left.tif", scene / "right.tif",
                                                     reference=scene / "reference.tif"),
                                     out=out, checkpoints=scene / "truth" / "checkpoints.json",
                                     self_calibrate=True, progress=False),
                        lidar=scene / "truth" / "lidar.laz",
                        landcover=scene / "truth" / "landcover.tif")
    mtime = (out / "dsm.tif").stat().st_mtime_ns
    outcome = pair_flow(params)
    return scene, out, params, outcome, mtime


def test_resume_keeps_the_orientation_and_adds_the_rest(pair_run):
    _, out, _, outcome, mtime = pair_run
    assert "orient" in outcome.skipped
    assert (out / "dsm.tif").stat().st_mtime_ns == mtime  # not rewritten
    for name in ("eval.json", "report.html", "report.md", "stac/catalog.json", "pair.json",
                 "ortho_left.tif", "ortho_right.tif", "ortho_compare.json",
                 "ortho_discrepancy.tif"):
        assert (out / name).is_file(), name
    assert pair_complete(out)


def test_the_two_orthos_share_a_grid_and_agree(pair_run):
    """Both images through their oriented models over the (SRTM-like) reference: one grid,
    and the same ground under the same cell to a fraction of a pixel."""
    _, out, _, _, _ = pair_run
    with rasterio.open(out / "ortho_left.tif") as a, rasterio.open(out / "ortho_right.tif") as b:
        assert a.crs == b.crs and a.res == b.res
        # aligned grids: the corners differ by whole cells
        off = np.array([a.transform.c - b.transform.c, a.transform.f - b.transform.f]) / a.res[0]
        assert np.allclose(off, np.round(off), atol=1e-6)
    cmp = json.loads((out / "ortho_compare.json").read_text())
    # 40 m pixels, canopy absent from the reference, 10 % changed between the dates, 0.3 px
    # of jitter: measured median 0.57 px, p95 1.7 px (before orientation: several pixels)
    assert cmp["n_valid"] >= 50
    assert cmp["px"]["median_norm"] < 1.0 and cmp["px"]["p95_norm"] < 3.0
    assert abs(cmp["px"]["median_dx"]) < 0.3 and abs(cmp["px"]["median_dy"]) < 0.3


def test_evaluation_is_the_final_dsm_against_the_lidar(pair_run):
    _, out, _, _, _ = pair_run
    ev = json.loads((out / "eval.json").read_text())
    assert ev["all"]["count"] > 1000
    assert set(ev["classes"])  # land-cover classes
    assert sum(c["count"] for c in ev["classes"].values()) == ev["all"]["count"]
    # the tiny pair has 40 m pixels: the DSM is good to tens of metres, not hundreds
    assert 0.0 < ev["all"]["le68"] < 60.0


def test_stac_items_describe_the_rasters_on_disk(pair_run):
    _, out, _, _, _ = pair_run
    catalog = pystac.Catalog.from_file(str(out / "stac" / "catalog.json"))
    items = {i.id: i for i in catalog.get_items(recursive=True)}
    assert "tiny-pair-dsm" in items and "tiny-pair-dsm_egm96" in items
    for item in items.values():
        (_key, asset), = item.assets.items()
        path = (out / "stac" / item.id / asset.href).resolve()
        with rasterio.open(path) as src:
            proj = ProjectionExtension.ext(item)
            assert proj.epsg == src.crs.to_epsg()
            if proj.epsg is None:  # a compound CRS (UTM + EGM96 heights): its WKT instead
                assert rasterio.crs.CRS.from_wkt(proj.wkt2) == src.crs
            assert list(proj.shape) == [src.height, src.width]
            west, south, east, north = transform_bounds(src.crs, "EPSG:4326", *src.bounds)
        # the bbox holds the raster's corners (pyproj, not the code under test)
        assert np.allclose(item.bbox, [west, south, east, north], atol=1e-3)


def test_a_damaged_product_is_redone_on_rerun(pair_run):
    _scene, out, params, _, mtime = pair_run
    (out / "eval.json").write_text("{ truncated")
    assert not pair_complete(out)
    outcome = pair_flow(params)
    assert "orient" in outcome.skipped and "evaluate" not in outcome.skipped
    assert json.loads((out / "eval.json").read_text())["all"]["count"] > 1000
    assert (out / "dsm.tif").stat().st_mtime_ns == mtime
    assert pair_complete(out)


@pytest.mark.parametrize("extra, says", [
    ([], "needs a reference DEM"),
    (["--reference", "{ref}", "--landcover", "{lc}"], "give --lidar too"),
    (["--reference", "{ref}", "--lidar", "{missing}"], "does not exist"),
])
def test_pair_command_refuses_bad_input_in_one_line(tiny_scene, tmp_path, capsys, extra, says):
    from flows.cli import main

    scene, _ = tiny_scene
    subs = {"ref": scene / "reference.tif", "lc": scene / "truth" / "landcover.tif",
            "missing": tmp_path / "none.laz"}
    argv = ["pair", "--left", str(scene / "left.tif"), "--right", str(scene / "right.tif"),
            *[a.format(**subs) for a in extra], "--out", str(tmp_path / "out")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and says in err[0] and err[0].startswith("gcpfree pair: error:")
    assert not (tmp_path / "out").exists()


class Reached(Exception):
    """The orientation was started."""


def test_a_changed_option_redoes_the_orientation_and_what_follows(pair_run, tmp_path,
                                                                   monkeypatch, capsys):
    """A rerun with another orientation option (here without self-calibration) must not keep
    the orientation made with the old one, nor the orthos and evaluation made from it; the
    same options keep it (the resume test above), and an archive rerun does the same."""
    import dataclasses

    import flows.orient
    from tasks.archive.pair import orientation_changes

    _scene, done, params, _, _ = pair_run
    out = tmp_path / "pair"
    shutil.copytree(done, out)
    same = dataclasses.replace(params, orient=dataclasses.replace(params.orient, out=out))
    changed = dataclasses.replace(same, orient=dataclasses.replace(same.orient,
                                                                   self_calibrate=False))
    defaults = manifest_defaults()
    assert pair_complete(out, same.to_dict(), defaults)
    assert not pair_complete(out, changed.to_dict(), defaults)
    # the options that only change how a run goes leave it complete
    quicker = dataclasses.replace(same, orient=dataclasses.replace(same.orient, workers=1),
                                  pair_id="x")
    assert pair_complete(out, quicker.to_dict(), defaults)

    def started(p):
        raise Reached(p)

    import prefect.artifacts

    monkeypatch.setattr(prefect.artifacts, "create_progress_artifact", lambda *a, **k: None)
    monkeypatch.setattr(flows.orient, "orient_flow", started)
    with pytest.raises(Reached):
        pair_flow.fn(changed)
    said = capsys.readouterr().out
    assert "orientation redone" in said and "self_calibrate" in said
    for name in ("pair.json", "ortho_left.tif", "ortho_right.tif", "ortho_compare.json",
                 "eval.json"):
        assert not (out / name).exists(), name
    assert (out / "report.json").is_file() and (out / "left.json").is_file()  # until replaced

    # a report of an older gcpfree (no settings recorded) is not trusted either
    report = json.loads((out / "report.json").read_text())
    settings = report.pop("settings")
    assert settings["self_calibrate"] is True and settings["left"].endswith("left.tif")
    (out / "report.json").write_text(json.dumps(report))
    assert orientation_changes(out, settings) == tuple(settings)
    assert orientation_changes(out) == ()  # the products read back
    (out / "left.json").unlink()
    assert orientation_changes(out, settings) is None

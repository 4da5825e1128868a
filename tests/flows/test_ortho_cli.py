"""``gcpfree ortho`` and ``gcpfree ortho-compare`` end to end on the tiny simulated scene: the
two images orthorectified with their truth models on the truth DSM (cubic resampling, an
occlusion mask), then compared (JSON, map, quiver); the parsers; bad input stopped in one
line before Prefect starts."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest
import rasterio

from core.errors import CoverageError, InputError
from flows.commands import ortho, ortho_compare


def parse(command, name: str, *argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="gcpfree")
    command.add_parser(parser.add_subparsers(dest="command"))
    return parser.parse_args([name, *argv])


def ortho_args(scene_dir: Path, name: str, out: Path, *extra: str) -> argparse.Namespace:
    return parse(ortho, "ortho", "--image", str(scene_dir / f"{name}.tif"),
                 "--model", str(scene_dir / "truth" / f"{name}_truth.json"),
                 "--dem", str(scene_dir / "truth" / "dsm.tif"), "--workers", "1",
                 "--out", str(out), *extra)


@pytest.fixture(scope="module")
def cli_orthos(prefect_harness, tiny_scene, tmp_path_factory):
    scene_dir, _ = tiny_scene
    out = tmp_path_factory.mktemp("ortho_cli")
    for name in ("left", "right"):
        extra = ("--resampling", "cubic", "--occlusion-mask", str(out / f"{name}_mask.tif"))
        assert ortho.run(ortho_args(scene_dir, name, out / f"{name}.tif", *extra)) == 0
    return scene_dir, out


def test_ortho_writes_a_cog_its_json_and_the_mask(cli_orthos, capsys):
    _, out = cli_orthos
    for name in ("left", "right"):
        with rasterio.open(out / f"{name}.tif") as src:
            assert src.crs.to_epsg() == 32631 and src.res == (40.0, 40.0)
            assert src.dtypes[0] == "uint8" and src.nodata == 0 and src.overviews(1)
            assert src.tags()["resampling"] == "cubic"
            valid = src.read(1) > 0
        with rasterio.open(out / f"{name}_mask.tif") as src:
            mask = src.read(1)
        assert ((mask != 255) == valid).mean() > 0.999
        doc = json.loads((out / f"{name}.json").read_text())
        assert doc["max_error_px"] <= 0.01 and doc["occlusion_path"].endswith("_mask.tif")


def test_ortho_compare_reports_numbers_a_map_and_a_quiver(cli_orthos, capsys):
    _, out = cli_orthos
    args = parse(ortho_compare, "ortho-compare", "--left", str(out / "left.tif"),
                 "--right", str(out / "right.tif"), "--out", str(out / "cmp.json"),
                 "--map", str(out / "cmp.tif"), "--quiver", str(out / "cmp.png"),
                 "--step", "64")
    assert ortho_compare.run(args) == 0
    printed = capsys.readouterr().out
    assert "discrepancy    median" in printed and "95th percentile" in printed
    doc = json.loads((out / "cmp.json").read_text())
    assert doc["n_valid"] > 20 and doc["px"]["median_norm"] < 0.35
    assert doc["m"]["median_norm"] == pytest.approx(40.0 * doc["px"]["median_norm"])
    assert len(doc["windows"]["dx_px"]) == doc["n_windows"]
    with rasterio.open(out / "cmp.tif") as src:
        norm = src.read(1)
        assert src.res == (64 * 40.0, 64 * 40.0) and src.crs.to_epsg() == 32631
    w = {k: np.array(v, dtype=float) for k, v in doc["windows"].items()}  # null -> NaN
    ok = w["status"] == 0
    np.testing.assert_allclose(np.sort(norm[np.isfinite(norm)]),
                               np.sort(np.hypot(w["dx_px"][ok], w["dy_px"][ok])), rtol=1e-6)
    assert (out / "cmp.png").read_bytes()[:4] == b"\x89PNG"


def test_bad_input_is_one_line_before_anything_runs(tiny_scene, tmp_path):
    scene_dir, _ = tiny_scene
    with pytest.raises(InputError, match="does not exist"):
        ortho.run(parse(ortho, "ortho", "--image", str(tmp_path / "none.tif"), "--dem",
                        str(scene_dir / "reference.tif"), "--out", str(tmp_path / "o.tif")))
    far = tmp_path / "far.tif"
    with rasterio.open(far, "w", driver="GTiff", width=10, height=10, count=1,
                       dtype="float32", crs="EPSG:4326",
                       transform=rasterio.Affine(0.01, 0, 10.0, 0, -0.01, 10.0)) as dst:
        dst.write(np.full((10, 10), 100.0, np.float32), 1)
    with pytest.raises(InputError, match="--dem-vertical egm96"):  # untagged: datum unknown
        ortho.run(parse(ortho, "ortho", "--image", str(scene_dir / "left.tif"), "--dem",
                        str(far), "--out", str(tmp_path / "o.tif")))
    with pytest.raises(CoverageError):
        ortho.run(parse(ortho, "ortho", "--image", str(scene_dir / "left.tif"), "--dem",
                        str(far), "--dem-vertical", "egm96", "--out", str(tmp_path / "o.tif")))
    with pytest.raises(InputError, match="projected"):
        ortho.run(ortho_args(scene_dir, "left", tmp_path / "o.tif", "--crs", "4326"))
    with pytest.raises(InputError, match="folder of --out"):
        ortho.run(ortho_args(scene_dir, "left", tmp_path / "no" / "o.tif"))
    with pytest.raises(InputError, match="does not exist"):
        ortho_compare.run(parse(ortho_compare, "ortho-compare", "--left",
                                str(tmp_path / "a.tif"), "--right", str(tmp_path / "b.tif"),
                                "--out", str(tmp_path / "c.json")))
    assert not (tmp_path / "o.tif").exists()


def test_orthos_off_one_lattice_are_refused(tiny_scene, tmp_path):
    scene_dir, _ = tiny_scene
    with rasterio.open(scene_dir / "truth" / "dsm.tif") as src:
        profile, z = src.profile, src.read(1)
    shifted = dict(profile, transform=profile["transform"] * rasterio.Affine.translation(0.5, 0))
    with rasterio.open(tmp_path / "shifted.tif", "w", **shifted) as dst:
        dst.write(z, 1)
    with pytest.raises(InputError, match="not on one lattice"):
        ortho_compare.run(parse(ortho_compare, "ortho-compare", "--left",
                                str(scene_dir / "truth" / "dsm.tif"), "--right",
                                str(tmp_path / "shifted.tif"), "--out",
                                str(tmp_path / "c.json")))
    with pytest.raises(InputError, match="not in a projected CRS"):
        ortho_compare.run(parse(ortho_compare, "ortho-compare", "--left",
                                str(scene_dir / "reference.tif"), "--right",
                                str(scene_dir / "truth" / "dsm.tif"), "--out",
                                str(tmp_path / "c.json")))


@pytest.mark.parametrize("command, name", [(ortho, "ortho"), (ortho_compare, "ortho-compare")])
def test_help_lists_the_options(command, name, capsys):
    with pytest.raises(SystemExit):
        parse(command, name, "--help")
    text = capsys.readouterr().out
    for option in (("--image", "--model", "--dem", "--dem-vertical", "--resolution", "--crs",
                    "--resampling", "--occlusion-mask", "--out") if name == "ortho"
                   else ("--left", "--right", "--out", "--map", "--quiver", "--window")):
        assert option in text

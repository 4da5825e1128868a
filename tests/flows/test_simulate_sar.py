"""``gcpfree simulate --sar``: the SAR product of the tiny scene read back by the Sentinel-1
reader (the grid check of ``info`` to the real files' tolerances), its corner reflectors
found in the image where the annotation's model with the TRUE orbit and timing puts them, the
truth differing from the annotation by exactly the drawn errors, and the same bytes from the
flow on the existing scene folder as from the task."""

from __future__ import annotations

import json
import shutil
import warnings
from dataclasses import replace
from functools import cache
from pathlib import Path

import numpy as np
import pytest
import rasterio
from rasterio.errors import NotGeoreferencedWarning

from core.errors import InputError
from core.sensors.orbit import orbital_frame
from core.sensors.sar import SarModel
from core.simulation.scene import SceneDef
from flows.cli import main
from tasks.io.sensors import load_model
from tasks.io.sentinel1 import read_annotation
from tasks.simulate.sar import SarPaths, simulate_sar
from tests.scenes import CENTRE

FILES = ("sar.tif", "sar.xml", "sar.json", "truth/sar_truth.json", "truth/sar.json",
         "truth/sar_mask.tif")


def _copy_scene(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns("sar*"))
    return dst


@pytest.fixture(scope="module")
def sar_scenes(tiny_scene, tmp_path_factory):
    """The tiny scene with an ERS-like and a Sentinel-1-like product, by the task."""
    src, _ = tiny_scene
    out = {}
    for name in ("ers", "s1"):
        d = _copy_scene(src, tmp_path_factory.mktemp("sar") / name)
        scene = SceneDef.from_json((d / "truth" / "scene.json").read_text())
        simulate_sar.fn(scene, d, name)
        out[name] = d
    return out


@cache
def _products(d: Path):
    sp = SarPaths(d)
    ann = read_annotation(sp.annotation)
    truth = SarModel.from_json(sp.truth_model.read_text())
    record = json.loads(sp.record.read_text())
    with warnings.catch_warnings():  # radar geometry, as Sentinel-1 measurement TIFFs
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        with rasterio.open(sp.image) as src:
            dn = src.read(1).astype(np.float64)
    return ann, truth, record, dn


@pytest.mark.parametrize("name", ["ers", "s1"])
def test_annotation_reads_back_and_passes_the_grid_check(sar_scenes, name, tmp_path):
    d = sar_scenes[name]
    ann, _, _, dn = _products(d)
    assert ann.model.kind == ("slc" if name == "ers" else "grd")
    assert dn.shape == (ann.model.n_rows, ann.model.n_cols)
    assert max(dn.shape) < 1000  # tiny: a few hundred pixels per side
    # the model beside the image is the annotation's, bit for bit
    assert SarModel.from_json((d / "sar.json").read_text()).to_json() == ann.model.to_json()
    lm = load_model(d / "sar.tif")
    assert lm.family == "sar" and lm.size == (ann.model.n_cols, ann.model.n_rows)
    # gcpfree info's grid check, to the tolerances the real S1 annotations meet
    out = tmp_path / "info.json"
    assert main(["info", str(d / "sar.xml"), "--json", str(out)]) == 0
    g = json.loads(out.read_text())["sar"]["grid_check"]
    assert g["n_points"] == 210
    assert g["pixel_max_px"] < 0.01 and g["line_max_px"] < 0.25
    assert g["azimuth_max_m"] < 0.015 and g["range_max_mm"] < 1.0


def _centroid(dn: np.ndarray, col: float, row: float) -> tuple[float, float]:
    """Centroid, above the local clutter, of the brightest 2x2 pixels within 3 px of (col,
    row): where a point target splatted bilinearly shows in the image."""
    i0, j0 = round(row) - 4, round(col) - 4
    w = dn[i0:i0 + 9, j0:j0 + 9] ** 2
    w = np.maximum(w - np.median(dn[i0 - 8:i0 + 17, j0 - 8:j0 + 17] ** 2), 0.0)
    sums = w[:-1, :-1] + w[1:, :-1] + w[:-1, 1:] + w[1:, 1:]
    i, j = np.unravel_index(np.argmax(sums), sums.shape)
    q = w[i:i + 2, j:j + 2]
    return (j0 + j + float(q[:, 1].sum() / q.sum()),
            i0 + i + float(q[1, :].sum() / q.sum()))


@pytest.mark.parametrize("name", ["ers", "s1"])
def test_reflectors_where_the_annotation_with_the_true_orbit_puts_them(sar_scenes, name):
    """(a) the annotation as read, given the true orbit and the drawn timing errors, puts the
    corner reflectors where the image shows them; (b) the truth is exactly that model, and the
    delivered annotation alone misses them by the drawn error."""
    ann, truth, record, dn = _products(sar_scenes[name])
    e = record["errors"]
    fixed = replace(ann.model, orbit=truth.orbit).with_params(
        [e["azimuth_offset_s"], e["range_delay_s"]])
    assert fixed.to_json() == truth.to_json()
    frame = orbital_frame(truth.orbit.positions_m, truth.orbit.velocities_m_s)
    moved = np.einsum("nji,nj->ni", frame, ann.model.orbit.positions_m - truth.orbit.positions_m)
    np.testing.assert_allclose(moved[3], [e["orbit_along_m"], e["orbit_across_m"],
                                          -e["orbit_radial_m"]], atol=1e-6)
    refl = record["reflectors"]
    assert len(refl) >= 3
    lon, lat, h = (np.array([r[k] for r in refl]) for k in ("lon_deg", "lat_deg", "h_m"))
    col, row = fixed.project(lon, lat, h)
    found = np.array([_centroid(dn, c, r) for c, r in zip(col, row, strict=True)])
    err_px = np.hypot(found[:, 0] - col, found[:, 1] - row)
    assert err_px.max() < 0.05, err_px
    # the delivered annotation alone misses them in the image by the drawn error
    col_d, row_d = ann.model.project(lon, lat, h)
    gr, az = record["figures"]["ground_spacing_m"]
    miss_m = np.hypot((found[:, 0] - col_d) * gr, (found[:, 1] - row_d) * az)
    assert np.all(np.abs(miss_m - record["centre_error_m"])
                  < 0.2 * record["centre_error_m"] + 0.05 * max(gr, az))
    miss_px = np.hypot(found[:, 0] - col_d, found[:, 1] - row_d)
    assert miss_px.min() > 2 * err_px.max()  # the image tells the truth from the annotation


@pytest.mark.parametrize("name", ["ers", "s1"])
def test_layover_and_shadow_mask(sar_scenes, name):
    with rasterio.open(SarPaths(sar_scenes[name]).mask) as src:
        mask = src.read(1)
    counts = np.bincount(mask.ravel(), minlength=4)
    # steep Vercors slopes: layover at 23 deg (ERS) far more than at 38 deg (S1), shadow the
    # other way round
    assert counts[2] + counts[3] > 0
    if name == "ers":
        assert counts[2] > 5 * _layover(sar_scenes["s1"])
    else:
        assert counts[1] + counts[3] > 100


def _layover(d: Path) -> int:
    with rasterio.open(SarPaths(d).mask) as src:
        m = src.read(1)
    return int(np.count_nonzero(m >= 2))


def test_cli_on_the_existing_scene_same_bytes(sar_scenes, tiny_scene, prefect_harness, tmp_path,
                                              capsys):
    """``gcpfree simulate --sar ers`` rerun on the scene's folder with its parameters adds the
    product (the optical products resume), byte for byte what the task made; another mission
    on that folder is refused in one line."""
    src, _ = tiny_scene
    d = _copy_scene(src, tmp_path / "scene")
    args = ["simulate", "--out", str(d), "--seed", "11", "--lens", "--jitter",
            "--date-change", "0.1", "--center", *map(str, CENTRE), "--sar", "ers"]
    assert main(args) == 0
    assert "corner reflectors" in capsys.readouterr().out
    for f in FILES:
        assert (d / f).read_bytes() == (sar_scenes["ers"] / f).read_bytes(), f
    scene = SceneDef.from_json((d / "truth" / "scene.json").read_text())
    with pytest.raises(InputError, match="already holds the ers SAR product") as e:
        simulate_sar.fn(scene, d, "s1")
    assert "\n" not in str(e.value)

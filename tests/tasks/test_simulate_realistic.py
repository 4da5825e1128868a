"""``gcpfree simulate --errors realistic`` on the tiny preset, without rendering: the scene
record, the SPOT metadata the chain reads, and the reference against the truth surface."""

from __future__ import annotations

import json

import numpy as np
import pytest
import rasterio

from core.sensors.dimap import parse_dimap
from core.sensors.pushbroom import PushbroomModel
from core.sensors.spot import spot_pushbroom
from core.simulation.hashing import derive_seed
from core.simulation.landcover import LandCover
from core.simulation.realistic import SPEED_QUANTUM_RAD_S
from core.simulation.reference import ReferenceErrors, canopy_fraction_seen
from core.simulation.scene import SceneDef, error_config
from core.simulation.surface import sample_surface
from tasks.io.crs import Projection
from tasks.simulate import scene as S
from tasks.simulate.io import ScenePaths, load_surface_spec
from tests.scenes import CENTRE, DEM


@pytest.fixture(scope="module")
def realistic(tmp_path_factory):
    """A tiny scene with realistic errors: scene, metadata and reference (no rendering)."""
    out = tmp_path_factory.mktemp("tiny_realistic")
    scene = S.define_scene.fn(DEM, out, "tiny", 4, error_config("tiny", "realistic", lens=True),
                              centre_lonlat=CENTRE)
    S.write_spot_metadata.fn(scene, out)
    S.make_reference.fn(scene, out)
    return out, scene


def test_scene_json_records_the_realistic_errors(realistic):
    out, scene = realistic
    back = SceneDef.from_json(ScenePaths(out).scene_json.read_text())
    assert back.errors.realistic and back.to_json() == scene.to_json()
    for n in scene.image_names:
        rec = back.injected[n].realistic
        assert rec is not None and rec.speed_quantum_rad_s == pytest.approx(3.4907e-7, rel=1e-4)
        assert len(rec.profile) > 0 and len(rec.segment_offsets_px) == 4


def test_dimap_states_quantised_speeds_and_reads_back_as_the_delivered_model(realistic):
    out, scene = realistic
    paths = ScenePaths(out)
    for n in scene.image_names:
        spot = parse_dimap(paths.dimap(n).read_text(), n)
        q = SPEED_QUANTUM_RAD_S
        for k in ("roll", "pitch", "yaw"):
            w = getattr(spot.aocs_speeds, k)
            assert np.allclose(w / q, np.round(w / q), atol=1e-6, rtol=0)
        delivered = PushbroomModel.from_json(paths.delivered(n).read_text())
        read = spot_pushbroom(spot)
        cols = np.array([0.0, 300.0, 599.0])
        lon, lat = delivered.localize(cols, cols[::-1], np.full(3, 600.0))
        c, r = read.project(lon, lat, np.full(3, 600.0))
        assert np.allclose(c, cols, atol=1e-3) and np.allclose(r, cols[::-1], atol=1e-3)


def test_reference_errors_recorded_and_voids_where_srtm_could_not_see(realistic):
    out, _ = realistic
    err = ReferenceErrors(**{k: tuple(v) if isinstance(v, list) else v for k, v in
                             json.loads((out / "truth" / "reference_errors.json").read_text())
                             .items()})
    assert err.canopy_seen == (0.3, 0.7) and 30 <= err.radar_incidence_deg <= 58
    assert np.hypot(err.shift_east_m, err.shift_north_m) <= 10.0
    assert err.void_share == 0.0  # SRTM's voids are its radar geometry's here
    with rasterio.open(out / "reference.tif") as src:
        h = src.read(1)
    assert 0 < np.isnan(h).mean() < 0.2  # Mont Ventoux's steep faces, not the plains


def test_reference_penetration_measured_against_the_truth_surface(realistic, tmp_path):
    """Canopy alone (no noise, shift, tilt or voids): over forest the reference minus the truth
    DTM is the drawn stand fraction of the truth canopy, node by node."""
    _, scene = realistic
    out = tmp_path / "scene"
    scene2 = S.define_scene.fn(DEM, out, "tiny", 4, scene.errors, centre_lonlat=CENTRE)
    err = ReferenceErrors(noise_m=0.0, void_share=0.0, canopy_seen=(0.3, 0.7))
    S.make_reference.fn(scene2, out, err)
    with rasterio.open(out / "reference.tif") as src:
        h, t = src.read(1).astype(np.float64), src.transform
    rows, cols = np.mgrid[0:h.shape[0]:7, 0:h.shape[1]:7]
    lon, lat = t.c + (cols + 0.5) * t.a, t.f + (rows + 0.5) * t.e
    proj = Projection(scene2.epsg)
    x, y = proj.to_xy(lon.ravel(), lat.ravel())
    s = sample_surface(load_surface_spec(scene2.to_json()), x, y, proj.to_lonlat)
    forest = (s.classes == LandCover.FOREST) & (s.dsm_m - s.dtm_m > 5.0)
    assert forest.sum() > 50
    measured = (h[rows, cols].ravel() - s.dtm_m)[forest] / (s.dsm_m - s.dtm_m)[forest]
    drawn = canopy_fraction_seen(x, y, derive_seed(scene2.seed, "reference"), err)[forest]
    # float32 heights: 1 mm over 10-25 m canopies
    assert np.allclose(measured, drawn, atol=2e-4)
    assert 0.3 - 1e-4 <= measured.min() and measured.max() <= 0.7 + 1e-4

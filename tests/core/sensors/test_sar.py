"""core.sensors.sar and core.sensors.sentinel1: the zero-Doppler model against the geolocation
grids of real Sentinel-1 annotations (stripmap SLC, IW GRD), round trips, the Jacobian, the
correctable parameters, and TOPS bursts on an annotation made from the SLC one."""

from __future__ import annotations

import json
import re
from dataclasses import replace
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from core.errors import InputError
from core.geodesy import geodetic_to_ecef
from core.sensors.base import SensorModel, numeric_jacobian
from core.sensors.sar import SarModel, grid_check
from core.sensors.sentinel1 import Annotation, parse_annotation

S1 = Path(__file__).resolve().parents[2] / "data" / "sentinel1"
SLC = S1 / "s1a-s3-slc-vh-20210401t152855-20210401t152914-037258-04638e-001.xml"
GRD = S1 / "s1b-iw-grd-vv-20210401t052623-20210401t052648-026269-032297-001.xml"
# (file, pixel max px, line max px): the bounds, and this model's figures with margin
FILES = [(SLC, 0.001, 0.25), (GRD, 0.01, 0.25)]


@cache
def annotation(path: Path) -> Annotation:
    return parse_annotation(path.read_text(), path.name)


def _ecef(lon, lat, h):
    return np.stack(geodetic_to_ecef(lon, lat, h), axis=-1)


@pytest.mark.parametrize(("path", "pixel_tol", "line_tol"), FILES, ids=["slc", "grd"])
def test_grid_reproduced(path, pixel_tol, line_tol):
    a = annotation(path)
    g = a.grid
    chk = grid_check(a.model, g.lon_deg, g.lat_deg, g.h_m, g.pixel, g.line, g.azimuth_time_s,
                     g.slant_range_time_s)
    assert chk.n_points == g.line.size > 200
    assert chk.pixel_max_px < pixel_tol  # SLC ~0.0006 px, GRD ~0.008 px (nearest srgr record)
    assert chk.line_max_px < line_tol  # the products' own line/time consistency: 0.1-0.2 px
    assert chk.azimuth_max_m < 0.015  # zero-Doppler time within 1.5 cm along track
    assert chk.range_max_mm < 1.0
    # localisation of the grid's line/pixel/h: off only by the grid's own line error
    along_m = a.model.along_track_speed_m_s(g.azimuth_time_s).max() * a.model.line_interval_s
    assert chk.ground_max_m < line_tol * along_m + 0.05


@pytest.mark.parametrize("path", [SLC, GRD], ids=["slc", "grd"])
def test_round_trips(path):
    m = annotation(path).model
    assert isinstance(m, SensorModel)
    cols = np.linspace(0, m.n_cols - 1, 7)
    rows = np.linspace(0, m.n_rows - 1, 5)
    c, r = (a.ravel() for a in np.meshgrid(cols, rows))
    for h in (-100.0, 0.0, 3000.0):
        hh = np.full(c.shape, h)
        lon, lat = m.localize(c, r, hh)
        c2, r2 = m.project(lon, lat, hh)
        np.testing.assert_allclose(c2, c, atol=1e-5)
        np.testing.assert_allclose(r2, r, atol=1e-5)
        lon3, lat3 = m.localize(c2, r2, hh)
        d = np.linalg.norm(_ecef(lon3, lat3, hh) - _ecef(lon, lat, hh), axis=-1)
        assert d.max() < 1e-3


@pytest.mark.parametrize("path", [SLC, GRD], ids=["slc", "grd"])
def test_jacobian_and_parameters(path):
    m = annotation(path).model
    g = annotation(path).grid
    lon, lat, h = g.lon_deg[::20], g.lat_deg[::20], g.h_m[::20]
    assert m.param_names == ("azimuth_offset_s", "range_delay_s")
    assert np.array_equal(m.params, [0.0, 0.0])
    num = numeric_jacobian(m, lon, lat, h, [m.line_interval_s, 1.0 / m.range_sampling_rate_hz])
    np.testing.assert_allclose(m.jacobian(lon, lat, h), num, rtol=1e-6, atol=1e-3)
    # a known timing and delay error: rows move by offset/dt, the point is found again
    m2 = m.with_params([3 * m.line_interval_s, 0.0])
    c0, r0 = m.project(lon, lat, h)
    c1, r1 = m2.project(lon, lat, h)
    np.testing.assert_allclose(r1 - r0, 3.0, atol=1e-6)
    np.testing.assert_allclose(c1, c0, atol=1e-6 if m.kind == "slc" else 0.02)
    m3 = m.with_params([0.0, 2e-8])  # 3 m of range
    c3, _ = m3.project(lon, lat, h)
    assert np.all(c3 - c0 > 0)
    lon3, lat3 = m3.localize(c3, r0, h)
    d = np.linalg.norm(_ecef(lon3, lat3, h) - _ecef(lon, lat, h), axis=-1)
    assert d.max() < 1e-3
    with pytest.raises(InputError):
        m.with_params([1.0])


def _tops_text(lines_per_burst: int, n_bursts: int, overlap_lines: int) -> str:
    """The SLC annotation turned into a TOPS one: bursts of ``lines_per_burst`` lines whose
    start times step by ``lines_per_burst - overlap_lines`` lines (consecutive bursts share
    ``overlap_lines`` lines of azimuth time, as IW bursts do)."""
    text = SLC.read_text()
    a = annotation(SLC)
    step = (lines_per_burst - overlap_lines) * a.model.line_interval_s
    t0 = np.datetime64(a.first_line_utc, "ns")
    starts = [np.datetime64(t0 + np.timedelta64(int(round(k * step * 1e9)), "ns"), "us")
              for k in range(n_bursts)]
    bursts = "".join(f"<burst><azimuthTime>{t}</azimuthTime></burst>" for t in starts)
    text = re.sub(r"<linesPerBurst>0</linesPerBurst>",
                  f"<linesPerBurst>{lines_per_burst}</linesPerBurst>", text)
    text = re.sub(r'<burstList count="0"\s*/>',
                  f'<burstList count="{n_bursts}">{bursts}</burstList>', text)
    return re.sub(r"<numberOfLines>\d+</numberOfLines>",
                  f"<numberOfLines>{lines_per_burst * n_bursts}</numberOfLines>", text)


def test_tops_bursts():
    lpb, nb, ov = 2000, 5, 200
    tops = parse_annotation(_tops_text(lpb, nb, ov), "tops.xml").model
    slc = annotation(SLC).model
    assert tops.kind == "tops" and tops.n_rows == lpb * nb
    burst_centres = np.arange(nb) * (lpb - ov) + 0.5 * (lpb - 1)  # in stripmap lines
    # the same azimuth time in stripmap lines and in burst lines
    cols = np.array([100.0, 9000.0, 18000.0])
    for k in range(nb):
        for local in (10.0, 1000.0, lpb - 250.0):
            srow = k * (lpb - ov) + local  # stripmap line of that time
            lon, lat = slc.localize(cols, np.full(3, srow), np.zeros(3))
            lon_t, lat_t = tops.localize(cols, np.full(3, k * lpb + local), np.zeros(3))
            np.testing.assert_allclose([lon_t, lat_t], [lon, lat], atol=1e-9)
            c, r = tops.project(lon, lat, np.zeros(3))
            np.testing.assert_allclose(c, cols, atol=1e-5)
            # the burst whose centre time is nearest is returned
            kk = int(np.argmin(np.abs(srow - burst_centres)))
            # (burst times are stated to the microsecond: 0.002 lines)
            assert np.allclose(r, kk * lpb + srow - kk * (lpb - ov), atol=3e-3)
    # points in the overlap of bursts 1 and 2 (stripmap lines 3600-3799): both lines localise
    # to the point; the line returned is in the burst whose centre is nearer (1 below 3699.5)
    for srow, burst in ((3650.0, 1), (3750.0, 2)):
        lon, lat = slc.localize(cols, np.full(3, srow), np.zeros(3))
        for b in (1, 2):
            lon_b, lat_b = tops.localize(cols, np.full(3, b * lpb + srow - b * (lpb - ov)),
                                         np.zeros(3))
            np.testing.assert_allclose([lon_b, lat_b], [lon, lat], atol=1e-9)
        _, r = tops.project(lon, lat, np.zeros(3))
        assert np.allclose(r, burst * lpb + srow - burst * (lpb - ov), atol=3e-3)


def test_refusals():
    text = GRD.read_text()
    with pytest.raises(InputError, match="not well-formed"):
        parse_annotation(text[: len(text) // 2], "cut.xml")
    with pytest.raises(InputError, match="not Sentinel-1"):
        parse_annotation(text.replace("<missionId>S1B</missionId>",
                                      "<missionId>RS2</missionId>"), "rs2.xml")
    with pytest.raises(InputError, match="not a Sentinel-1 product annotation"):
        parse_annotation("<Dimap_Document/>", "other.xml")
    with pytest.raises(InputError, match="sr0"):
        parse_annotation(re.sub(r"<sr0>[^<]*</sr0>", "", text, count=1), "nosr0.xml")
    with pytest.raises(InputError, match="not a number"):
        parse_annotation(text.replace("<rangeSamplingRate>", "<rangeSamplingRate>x", 1), "x.xml")
    with pytest.raises(InputError):
        replace(annotation(SLC).model, kind="tops")  # no bursts
    assert isinstance(annotation(GRD).model, SarModel)


def test_utc_and_line_of_sight():
    a = annotation(SLC)
    m, g = a.model, a.grid
    assert m.utc_of_times([m.first_line_time_s])[0] == a.first_line_utc + "Z"
    los = m.line_of_sight_ecef(g.pixel[:5], g.line[:5], g.h_m[:5])
    assert np.allclose(np.linalg.norm(los, axis=1), 1.0)


def _models() -> list[SarModel]:
    return [annotation(SLC).model, annotation(GRD).model,
            parse_annotation(_tops_text(2000, 5, 200), "tops.xml").model]


@pytest.mark.parametrize("index", [0, 1, 2], ids=["slc", "grd", "tops"])
def test_json_round_trip_keeps_corrections_and_crop(index):
    """An adjusted model (azimuth offset, range delay), whole or cropped, written to JSON and
    read back projects and localises as before to 1e-9 px and keeps its parameters."""
    product = _models()[index].with_params([1.25e-3, -3.5e-8])
    for m in (product, product.with_image_window(37.0, 21.0, 200, 150)):
        back = SarModel.from_json(json.dumps(json.loads(m.to_json())))
        assert back.kind == m.kind and (back.n_cols, back.n_rows) == (m.n_cols, m.n_rows)
        np.testing.assert_array_equal(back.params, m.params)
        assert (back.col0_px, back.row0_px) == (m.col0_px, m.row0_px)
        assert back.to_dict() == m.to_dict()
        c, r = np.meshgrid(np.linspace(0, m.n_cols - 1, 4), np.linspace(0, m.n_rows - 1, 4))
        h = np.linspace(-50.0, 2000.0, c.size)
        lon, lat = m.localize(c.ravel(), r.ravel(), h)
        lon2, lat2 = back.localize(c.ravel(), r.ravel(), h)
        np.testing.assert_allclose([lon2, lat2], [lon, lat], rtol=0, atol=1e-12)
        np.testing.assert_allclose(np.stack(back.project(lon, lat, h)),
                                   np.stack(m.project(lon, lat, h)), rtol=0, atol=1e-9)


@pytest.mark.parametrize("index", [0, 1, 2], ids=["slc", "grd", "tops"])
def test_image_window_is_the_product_moved(index):
    """A crop's pixel (c, r) is the product's (c + col0, r + row0), both ways."""
    m = _models()[index].with_params([2e-4, 1e-8])
    crop = m.with_image_window(1037.0, 1021.0, 300, 250)
    c, r = np.meshgrid(np.linspace(0, 299, 4), np.linspace(0, 249, 4))
    c, r = c.ravel(), r.ravel()
    lon, lat = m.localize(c + 1037.0, r + 1021.0, 300.0)
    lon2, lat2 = crop.localize(c, r, 300.0)
    np.testing.assert_allclose([lon2, lat2], [lon, lat], rtol=0, atol=1e-11)
    np.testing.assert_allclose(np.stack(crop.project(lon, lat, 300.0)), [c, r], atol=1e-5)
    np.testing.assert_allclose(crop.jacobian(lon, lat, 300.0), m.jacobian(lon, lat, 300.0),
                               rtol=1e-12)
    # a crop of a crop composes; a crop outside the image is refused
    sub = crop.with_image_window(10.0, 20.0, 50, 50)
    assert (sub.col0_px, sub.row0_px) == (1047.0, 1041.0)
    with pytest.raises(InputError, match="does not fit"):
        crop.with_image_window(290.0, 0.0, 20, 20)


def test_json_refusals():
    d = annotation(GRD).model.to_dict()
    with pytest.raises(InputError, match="not a SAR model"):
        SarModel.from_dict({**d, "format": "gcpfree.pushbroom"})
    del d["grd"]["srgr_sr0_m"]
    with pytest.raises(InputError, match=r"SAR model: key 'grd.srgr_sr0_m' is missing") as e:
        SarModel.from_dict(d)
    assert "pushbroom" not in str(e.value)
    d = annotation(SLC).model.to_dict()
    with pytest.raises(InputError, match="corrections"):
        SarModel.from_dict({**d, "corrections": {"roll_bias": 1.0}})
    with pytest.raises(InputError, match="SAR kind"):
        SarModel.from_dict({**d, "kind": "scansar"})

"""SPOT Level 1A metadata -> rigorous model: conventions, the writer/reader round trip, the real
SPOT 2 and SPOT 5 files (skipped when ../shared is absent), and bad files."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from core.errors import InputError
from core.geodesy import geodetic_to_ecef
from core.points import GeoPoint
from core.sensors.dimap import dimap_xml, parse_dimap
from core.sensors.orbit import rotation_rpy
from core.sensors.spot import (
    SpotAngles,
    SpotLookAngles,
    frame_errors_m,
    integrated_attitude,
    look_table,
    rotation_to_rpy,
    rotation_to_spot,
    spot_pushbroom,
    spot_rotation,
    spot_scene_from_model,
)
from core.simulation.scene import PRESETS, ErrorConfig, scene_models
from tasks.io.dimap import read_dimap

SHARED = Path(__file__).resolve().parents[4] / "shared" / "data" / "spot_dimap"
REAL = pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data/spot_dimap is absent")


@pytest.fixture(scope="module")
def delivered():
    """Delivered models of the simulator's across-track (tiny) and along-track (hrs) pairs."""
    out = {}
    for preset in ("tiny", "hrs"):
        ms = scene_models(PRESETS[preset], GeoPoint(5.25, 44.2, 858.9), ErrorConfig(), 7)
        out.update({f"{preset}_{n}": m.delivered for n, m in ms.items()})
    return out


# -- conventions ------------------------------------------------------------------------------
def test_spot_rotation_is_the_handbook_matrix_in_our_axes():
    """SPOT: navigation -> orbital is Rx(-PITCH) Ry(-ROLL) Rz(YAW) in SPOT axes (X right,
    Y forward, Z up); ours are (x forward, y right, z down): a fixed change of basis."""
    def rx(a):
        return np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])

    def ry(a):
        return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])

    def rz(a):
        return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])

    basis = np.array([[0, 1, 0], [1, 0, 0], [0, 0, -1]])  # ours <- SPOT axes
    rng = np.random.default_rng(0)
    for roll, pitch, yaw in rng.uniform(-0.05, 0.05, (5, 3)):
        spot = rx(-pitch) @ ry(-roll) @ rz(yaw)
        np.testing.assert_allclose(spot_rotation(roll, pitch, yaw), basis @ spot @ basis.T,
                                   atol=1e-15)


def test_rotation_decompositions_invert_the_compositions():
    rng = np.random.default_rng(1)
    a = rng.uniform(-0.4, 0.4, (3, 50))
    np.testing.assert_allclose(rotation_to_spot(spot_rotation(*a)), a, atol=1e-14)
    np.testing.assert_allclose(rotation_to_rpy(rotation_rpy(*a)), a, atol=1e-14)
    # to first order SPOT's angles are ours with the signs flipped (second order: 1e-13)
    small = 1e-6 * a
    np.testing.assert_allclose(rotation_to_rpy(spot_rotation(*small)), -small, atol=1e-12)


def test_integrated_attitude_adds_the_speeds_to_the_absolute_angle():
    t = np.array([0.0, 1.0])
    angles = SpotAngles(t, np.array([1e-6, 9.0]), np.zeros(2), np.zeros(2), np.zeros(2, bool))
    ts = np.arange(1, 9) * 0.125
    speeds = SpotAngles(ts, np.full(8, 2e-6), np.arange(8) * 1e-7, np.zeros(8),
                        np.array([False] * 7 + [True]))
    a = integrated_attitude(angles, speeds)
    np.testing.assert_allclose(a.times_s, np.r_[0.0, ts])
    np.testing.assert_allclose(a.roll, 1e-6 + 2e-6 * np.r_[0.0, ts], atol=1e-18)
    # pitch: the rectangle rule with each speed over the interval ending at its time; the
    # last speed is out of range and replaced by its valid neighbour (6e-7)
    rates = np.r_[np.arange(7) * 1e-7, 6e-7]
    np.testing.assert_allclose(a.pitch, np.r_[0.0, np.cumsum(rates * 0.125)], atol=1e-18)


def test_two_detector_look_angles_lie_on_a_straight_line_of_unit_vectors():
    look = SpotLookAngles(1, np.array([1, 6000]), np.array([0.0099, 0.0099]),
                          np.array([-0.0955, 0.0145]))
    table = look_table(look, 6000)
    x, y = table.detector_xy(np.arange(6000.0))
    u = np.stack([x, y, np.ones_like(x)], axis=1)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    ends = u[[0, -1]]
    # the ends are the file's: x = tan PSI_X, y = -tan PSI_Y
    np.testing.assert_allclose(x[[0, -1]], np.tan(look.psi_x_rad), atol=1e-15)
    np.testing.assert_allclose(y[[0, -1]], -np.tan(look.psi_y_rad), atol=1e-15)
    # every direction is in the plane of the two end directions, and on the chord's rays at
    # the uniform parameter: normalise((1 - s) u1 + s uN)
    s = np.arange(6000.0) / 5999.0
    chord = (1 - s)[:, None] * ends[0] + s[:, None] * ends[1]
    chord /= np.linalg.norm(chord, axis=1, keepdims=True)
    np.testing.assert_allclose(u, chord, atol=1e-12)


# -- the simulator's metadata round trip -----------------------------------------------------------
@pytest.mark.parametrize("mission", [2, 5])
@pytest.mark.parametrize("name", ["tiny_left", "tiny_right", "hrs_left", "hrs_right"])
def test_metadata_round_trip_projects_within_a_thousandth_of_a_pixel(delivered, name, mission):
    """Model -> SPOT 1-4 (2) or SPOT 5 (5) METADATA.DIM text -> parsed -> model: every point of
    the scene, over the height range, projects where the original model puts it."""
    m = delivered[name]
    xml = dimap_xml(spot_scene_from_model(m, mission_index=mission))
    scene = parse_dimap(xml)
    assert scene.mission_index == mission
    assert (scene.aocs_speeds is not None) == (mission != 5)
    assert scene.look_angles[0].detector_ids.size == (m.n_cols if mission == 5 else 2)
    back = spot_pushbroom(scene)
    c, r = np.meshgrid(np.linspace(0, m.n_cols - 1, 13), np.linspace(0, m.n_rows - 1, 13))
    for h in (-200.0, 800.0, 3000.0):
        lon, lat = m.localize(c.ravel(), r.ravel(), h)
        c2, r2 = back.project(lon, lat, h)
        assert np.hypot(c2 - c.ravel(), r2 - r.ravel()).max() < 1e-3
    # the stated corners are what the producer's computation gives
    assert frame_errors_m(scene).max() < 1e-6


def test_spot14_style_states_inertial_velocities_and_small_attitudes(delivered):
    m = delivered["tiny_left"]
    scene = spot_scene_from_model(m, mission_index=2)
    assert scene.orbit.velocity_frame == "inertial"
    w = np.array([0.0, 0.0, 7.2921150e-5])
    np.testing.assert_allclose(scene.orbit.velocities_m_s - m.orbit.velocities_m_s,
                               np.cross(w, m.orbit.positions_m), atol=1e-9)
    # the mirror (about 22-23 deg at this incidence) is in the look angles, not the attitude
    assert 20 < np.degrees(scene.look_angles[0].psi_y_rad).mean() < 25
    assert np.abs(scene.aocs_angles.roll).max() < 1e-3
    # incidence stated as SPOT does: positive, the satellite west of the scene
    assert scene.incidence_deg == pytest.approx(25.5, abs=0.1)


def test_lens_distortion_cannot_be_stated(delivered):
    from dataclasses import replace

    from core.sensors.linear_array import LensDistortion

    m = replace(delivered["tiny_left"], distortion=LensDistortion(k3=0.01))
    with pytest.raises(InputError, match="lens distortion"):
        spot_scene_from_model(m)


# -- real products ---------------------------------------------------------------------------------
@REAL
@pytest.mark.parametrize(("name", "limit_m"), [("SPOT2.DIM", 5.0), ("SPOT5.DIM", 1.0)])
def test_real_products_reproduce_their_stated_corners(name, limit_m):
    """The corners and centre the producer states (h = 0; SPOT 1-4 without attitude), from
    ephemeris, look angles, line timing and (SPOT 5) the corrected attitudes."""
    scene = read_dimap(SHARED / name)
    err = frame_errors_m(scene)
    assert err.size == 5 and err.max() < limit_m, err


@REAL
def test_real_spot2_conventions_cost_what_the_module_says():
    """The wrong choices are far off: the tests of the conventions themselves."""
    from dataclasses import replace

    scene = read_dimap(SHARED / "SPOT2.DIM")
    assert scene.mission_index == 2 and scene.orbit.velocity_frame == "inertial"
    good = frame_errors_m(scene).max()
    flipped = replace(scene, look_angles=tuple(
        replace(la, psi_y_rad=-la.psi_y_rad) for la in scene.look_angles))
    assert frame_errors_m(flipped).min() > 1e4  # 39-159 km
    ecef = replace(scene, orbit=replace(scene.orbit, velocity_frame="ecef",
                                        velocities_m_s=scene.orbit.velocities_m_s - np.cross(
                                            [0, 0, 7.2921150e-5], scene.orbit.positions_m)))
    assert frame_errors_m(ecef).min() > 1e3  # the frame from dP/dt: kilometres
    shifted = replace(scene, centre_line=scene.centre_line + 1.0)
    assert frame_errors_m(shifted).min() > 5.0 > good


@REAL
def test_real_spot5_measured_attitude_matters_and_incidence_agrees():
    scene = read_dimap(SHARED / "SPOT5.DIM")
    assert scene.mission_index == 5 and scene.look_angles[0].detector_ids.size == 12000
    none = spot_pushbroom(scene, attitude="none")
    c = np.array([p.col - 1 for p in scene.frame])
    r = np.array([p.row - 1 for p in scene.frame])
    lon, lat = none.localize(c, r, np.zeros(5))
    a = np.stack(geodetic_to_ecef(lon, lat, 0.0), axis=-1)
    b = np.stack(geodetic_to_ecef([p.lon_deg for p in scene.frame],
                                  [p.lat_deg for p in scene.frame], 0.0), axis=-1)
    assert np.linalg.norm(a - b, axis=1).min() > 500.0  # without the corrected attitude
    spot2 = read_dimap(SHARED / "SPOT2.DIM")
    inc, across, _ = spot_pushbroom(spot2).viewing_geometry(2999.0, 2999.0, 0.0)
    assert np.copysign(float(inc), float(across)) == pytest.approx(spot2.incidence_deg, abs=0.01)


# -- bad files ---------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def good_xml(delivered) -> str:
    return dimap_xml(spot_scene_from_model(delivered["tiny_left"], mission_index=5))


def test_other_profiles_and_formats_say_what_they_are(good_xml):
    dimap_v2 = (Path(__file__).resolve().parents[2] / "data" / "dimap").glob("*.XML")
    with pytest.raises(InputError, match="DIMAP v2"):
        parse_dimap(next(dimap_v2).read_text())
    with pytest.raises(InputError, match="SPOTSCENE_2A.*Level 1A"):
        parse_dimap(good_xml.replace(">SPOTSCENE_1A<", ">SPOTSCENE_2A<"))
    with pytest.raises(InputError, match="not a DIMAP document"):
        parse_dimap("<kml></kml>")
    with pytest.raises(InputError, match="not well-formed XML"):
        parse_dimap(good_xml[: len(good_xml) // 2])


def test_inconsistent_files_give_one_line(good_xml):
    times = re.findall(r"<TIME>([^<]+)</TIME>", good_xml.split("<Ephemeris>")[1])
    swapped = good_xml.replace(times[1], "SWAP").replace(times[2], times[1]).replace("SWAP",
                                                                                     times[2])
    with pytest.raises(InputError, match="ephemeris times are not increasing"):
        parse_dimap(swapped)
    no_eph = re.sub(r"<Points>.*</Points>", "<Points/>", good_xml, flags=re.S)
    with pytest.raises(InputError, match="Ephemeris holds 0 point"):
        parse_dimap(no_eph)
    one_less = re.sub(r"<Look_Angles>\s*<DETECTOR_ID>600</DETECTOR_ID>.*?</Look_Angles>", "",
                      good_xml, flags=re.S)
    with pytest.raises(InputError, match="599 look angles for 600 columns"):
        parse_dimap(one_less)
    with pytest.raises(InputError, match="LINE_PERIOD"):
        parse_dimap(re.sub(r"<LINE_PERIOD>[^<]+<", "<LINE_PERIOD>fast<", good_xml))
    for err in (InputError,):
        with pytest.raises(err) as info:
            parse_dimap(re.sub(r"<NCOLS>\d+</NCOLS>", "", good_xml))
        assert "NCOLS" in str(info.value) and "\n" not in str(info.value)

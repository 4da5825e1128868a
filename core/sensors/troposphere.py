"""The troposphere's delay of a radar's range: its hydrostatic part, which a standard atmosphere
predicts, taken out of a SAR product's timing.

A SAR product's range times include the path delay through the troposphere: about 2.3 m at
zenith at sea level (one way), almost all of it hydrostatic, which the surface pressure sets
to millimetres (Saastamoinen 1972: ``ZHD = 0.0022768 P / (1 - 0.00266 cos 2 phi - 0.00028 H)``
with ``P`` in hPa and ``H`` in km), mapped to the line of sight by ``1 / cos(incidence)``.
Uncorrected, it moves SAR points away from the radar by ``delay / sin(incidence)`` on the
ground: about 6 m for ERS at 23 degrees, 5 m for Sentinel-1 at 38 (Schubert et al. 2017, who
find it the largest term of Sentinel-1's absolute geolocation). What stays is the wet part,
5-30 cm at zenith at mid latitudes, which no standard atmosphere predicts: the SAR frame's
prior keeps it (:func:`core.orientation.sar_gcps.sar_frame`).
"""

from __future__ import annotations

import numpy as np

SPEED_OF_LIGHT_M_S = 299_792_458.0
#: the standard atmosphere's pressure at sea level (hPa) and its fall with height
SEA_LEVEL_HPA = 1013.25


def standard_pressure_hpa(h_m: float) -> float:
    """The standard atmosphere's pressure at height ``h_m`` (ICAO, troposphere)."""
    return float(SEA_LEVEL_HPA * (1.0 - 2.25577e-5 * h_m) ** 5.25588)


def hydrostatic_zenith_delay_m(h_m: float, lat_deg: float) -> float:
    """Saastamoinen's zenith hydrostatic delay (one way, m) under the standard atmosphere's
    pressure at ``h_m``."""
    p = standard_pressure_hpa(h_m)
    return float(0.0022768 * p / (1.0 - 0.00266 * np.cos(2.0 * np.radians(lat_deg))
                                  - 0.00028 * h_m / 1000.0))


def standard_tropospheric_delay_m(h_m: float, lat_deg: float, incidence_deg: float) -> float:
    """The hydrostatic slant delay (one way, m) at ``incidence_deg``."""
    return hydrostatic_zenith_delay_m(h_m, lat_deg) / float(np.cos(np.radians(incidence_deg)))


def incidence_deg(model: object, lon_deg: float, lat_deg: float, h_m: float) -> float:
    """The radar's incidence at a ground point: the angle between its line of sight
    (``model.line_of_sight_ecef``, a :class:`core.sensors.sar.SarModel`) and the ellipsoid's
    normal there."""
    col, row = model.project(np.array([lon_deg]), np.array([lat_deg]),  # type: ignore[attr-defined]
                             np.array([h_m]))
    los = model.line_of_sight_ecef(col, row, np.array([h_m]))[0]  # type: ignore[attr-defined]
    lo, la = np.radians(lon_deg), np.radians(lat_deg)
    up = np.array([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)])
    return float(np.degrees(np.arccos(np.clip(los @ up, -1.0, 1.0))))


def with_standard_troposphere(model: object, lon_deg: float, lat_deg: float, h_m: float
                              ) -> tuple[object, float]:
    """The SAR ``model`` with the standard atmosphere's hydrostatic delay at the scene's centre
    (``lon_deg``, ``lat_deg``, ``h_m``) added to its range delay (two way), and that delay
    (one-way slant metres)."""
    d = standard_tropospheric_delay_m(h_m, lat_deg, incidence_deg(model, lon_deg, lat_deg, h_m))
    p = np.asarray(model.params, dtype=np.float64).copy()  # type: ignore[attr-defined]
    p[1] += 2.0 * d / SPEED_OF_LIGHT_M_S
    return model.with_params(p), d  # type: ignore[attr-defined]



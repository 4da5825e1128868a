"""The RPC00B standard as files and metadata carry it: the rational functions of its 20
monomials (evaluation, derivatives) and the text formats RPCs come in, each read into the fields
of :class:`core.sensors.rpc.RPCModel` (whose named constructors call these functions).

The monomial order is in :mod:`core.sensors.rpc`'s docstring. Pixel conventions of each
source (all converted to ours, 0-based with pixel centres at integers):

- OSSIM ``.geom`` keyword lists: 0-based, pixel centres at integers (ours; taken as is). Checked
  on the Ventoux Pleiades image 690908101-001: the ``.geom`` offsets are exactly the DIMAP ones
  minus 1 and the two models project identically.
- GDAL RPC metadata domain (GeoTIFF RPC tag, ``_RPC.TXT``): 0-based, pixel centres at integers
  (taken as is). GDAL's own RPC transformer reports pixel-corner coordinates, i.e. ours + 0.5.
- Pleiades / SPOT 6-7 DIMAP v2 RPC XML: 1-based (top-left pixel centre is (1, 1));
  :func:`dimap_xml_fields` subtracts 1 from ``SAMP_OFF`` and ``LINE_OFF``.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError

FloatArray = NDArray[np.float64]

# GDAL RPC metadata keys of the scalar fields, and of the coefficient fields.
GDAL_SCALARS = {
    "col_off": "SAMP_OFF", "col_scale": "SAMP_SCALE", "row_off": "LINE_OFF",
    "row_scale": "LINE_SCALE", "lon_off": "LONG_OFF", "lon_scale": "LONG_SCALE",
    "lat_off": "LAT_OFF", "lat_scale": "LAT_SCALE", "alt_off": "HEIGHT_OFF",
    "alt_scale": "HEIGHT_SCALE",
}
GDAL_COEFFS = {
    "col_num": "SAMP_NUM_COEFF", "col_den": "SAMP_DEN_COEFF",
    "row_num": "LINE_NUM_COEFF", "row_den": "LINE_DEN_COEFF",
}
# rpcm-style optional keys for the inverse polynomials (GDAL ignores them).
GDAL_INVERSE = {
    "lon_num": "LON_NUM_COEFF", "lon_den": "LON_DEN_COEFF",
    "lat_num": "LAT_NUM_COEFF", "lat_den": "LAT_DEN_COEFF",
}

_CHUNK = 8_192  # points per block when evaluating polynomials (blocks stay in cache)


def _derivative_matrices() -> tuple[FloatArray, FloatArray]:
    """(DX, DY), 20x20: ``coeffs @ DX`` are the coefficients (same monomial basis) of the
    derivative of the cubic with respect to x (= L or C), ``coeffs @ DY`` with respect to y."""
    # d(monomial i)/dx = factor * monomial j, as (i, j, factor); basis order in the module doc
    dx = [(1, 0, 1), (4, 2, 1), (5, 3, 1), (7, 1, 2), (10, 6, 1), (11, 7, 3), (12, 8, 1),
          (13, 9, 1), (14, 4, 2), (17, 5, 2)]
    dy = [(2, 0, 1), (4, 1, 1), (6, 3, 1), (8, 2, 2), (10, 5, 1), (12, 4, 2), (14, 7, 1),
          (15, 8, 3), (16, 9, 1), (18, 6, 2)]
    mats = []
    for table in (dx, dy):
        m = np.zeros((20, 20))
        for i, j, f in table:
            m[i, j] = f
        mats.append(m)
    return mats[0], mats[1]


DX, DY = _derivative_matrices()


def rational_functions(
    coeffs: FloatArray,
    x: FloatArray,
    y: FloatArray,
    z: FloatArray,
    offsets: tuple[float, float, float] = (0.0, 0.0, 0.0),
    scales: tuple[float, float, float] = (1.0, 1.0, 1.0),
    *,
    divide: bool = True,
) -> FloatArray:
    """Evaluate rational functions (or plain cubics) that share the 20 monomials.

    ``coeffs`` is (2k, 20) with rows paired (num_0, den_0, num_1, den_1, ...); x, y, z are 1-D
    and are normalised here as ``(x - offsets[0]) / scales[0]`` etc. Returns the (k, n) ratios,
    or with ``divide=False`` the (2k, n) values of every row of ``coeffs``.
    Works block by block in a reused monomial buffer (one matrix product per block), which
    keeps the work in cache and avoids temporaries.
    """
    n = x.size
    k = coeffs.shape[0] // 2
    out = np.empty((k if divide else coeffs.shape[0], n))
    width = min(_CHUNK, max(n, 1))
    buf = np.empty((20, width))
    buf[0] = 1.0
    vals = np.empty((coeffs.shape[0], width))
    inv = [1.0 / s for s in scales]
    mul = np.multiply
    for s in range(0, n, width):
        e = min(s + width, n)
        w = e - s
        m = buf[:, :w]
        for row, src, off, iscale in zip((1, 2, 3), (x, y, z), offsets, inv, strict=True):
            np.subtract(src[s:e], off, out=m[row])
            m[row] *= iscale
        mx, my, mz = m[1], m[2], m[3]
        mul(mx, my, out=m[4])
        mul(mx, mz, out=m[5])
        mul(my, mz, out=m[6])
        mul(mx, mx, out=m[7])
        mul(my, my, out=m[8])
        mul(mz, mz, out=m[9])
        mul(m[4], mz, out=m[10])
        mul(m[7], mx, out=m[11])
        mul(mx, m[8], out=m[12])
        mul(mx, m[9], out=m[13])
        mul(m[7], my, out=m[14])
        mul(m[8], my, out=m[15])
        mul(my, m[9], out=m[16])
        mul(m[7], mz, out=m[17])
        mul(m[8], mz, out=m[18])
        mul(m[9], mz, out=m[19])
        if not divide:
            np.matmul(coeffs, m, out=out[:, s:e])
            continue
        v = vals[:, :w]
        np.matmul(coeffs, m, out=v)
        for i in range(k):
            np.divide(v[2 * i], v[2 * i + 1], out=out[i, s:e])
    return out


def parse_number(key: str, value: Any) -> float:
    """A float from a metadata value that may carry a unit ("1234.5 pixels")."""
    if isinstance(value, (int, float, np.floating, np.integer)):
        return float(value)
    tokens = str(value).split()
    if not tokens:
        raise InputError(f"RPC key {key!r} is empty; give a number")
    try:
        return float(tokens[0])
    except ValueError:
        raise InputError(f"RPC key {key!r} is not a number: {value!r}; fix the RPC file") from None


def parse_coeffs(key: str, value: Any) -> FloatArray:
    """20 coefficients from a space-separated string or a sequence."""
    tokens = value.split() if isinstance(value, str) else list(np.ravel(value))
    if len(tokens) != 20:
        raise InputError(
            f"RPC key {key!r} holds {len(tokens)} coefficients, expected 20; fix the RPC file"
        )
    try:
        return np.array([float(t) for t in tokens], dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"RPC key {key!r} holds a non-numeric coefficient; fix the RPC file") from None


def _get(d: Mapping[str, Any], key: str, source: str) -> Any:
    if key not in d:
        raise InputError(f"RPC key {key!r} is missing from the {source}; give a complete RPC")
    return d[key]


# ------------------------------------------------------------------ formats


def geom_fields(text: str) -> dict[str, Any]:
    """The model's fields from the text of an OSSIM keyword list (``.geom``, ``key: value`` lines).

    Pixel convention: 0-based, pixel centres at integers (ours). Only the RPC00B
    polynomial format ("B") is accepted. OSSIM ``adjustment_*`` parameters are ignored.
    """
    d: dict[str, str] = {}
    for line in text.splitlines():
        key, sep, value = line.partition(":")
        if sep:
            d[key.strip().lower()] = value.strip()
    if not d:
        raise InputError("the .geom text is empty or holds no 'key: value' lines")
    fmt = d.get("polynomial_format", "B").strip().upper()
    if fmt != "B":
        raise InputError(f"RPC polynomial_format {fmt!r} is not supported; only RPC00B ('B')")
    kw: dict[str, Any] = {}
    for name, gkey in GDAL_SCALARS.items():
        key = gkey.lower()
        kw[name] = parse_number(key, _get(d, key, ".geom keyword list"))
    for name, gkey in GDAL_COEFFS.items():
        prefix = gkey.lower()
        kw[name] = np.array([
            parse_number(f"{prefix}_{i:02d}", _get(d, f"{prefix}_{i:02d}", ".geom keyword list"))
            for i in range(20)
        ])
    return kw

def gdal_tag_fields(tags: Mapping[str, Any]) -> dict[str, Any]:
    """The model's fields from the GDAL RPC metadata domain (``rasterio`` ``src.tags(ns="RPC")``).

    Values may carry a unit ("19999.5 pixels"). Pixel convention: 0-based, pixel centres at
    integers (ours). The optional rpcm-style keys ``LON_NUM_COEFF``, ``LON_DEN_COEFF``,
    ``LAT_NUM_COEFF``, ``LAT_DEN_COEFF`` give the inverse polynomial.
    """
    if not tags:
        raise InputError("the RPC metadata is empty; the raster holds no RPC")
    d = {str(k).upper(): v for k, v in tags.items()}
    kw: dict[str, Any] = {}
    for name, key in GDAL_SCALARS.items():
        kw[name] = parse_number(key, _get(d, key, "GDAL RPC metadata"))
    for name, key in GDAL_COEFFS.items():
        kw[name] = parse_coeffs(key, _get(d, key, "GDAL RPC metadata"))
    if any(k in d for k in GDAL_INVERSE.values()):
        for name, key in GDAL_INVERSE.items():
            kw[name] = parse_coeffs(key, _get(d, key, "GDAL RPC metadata"))
    return kw

def dimap_xml_fields(text: str) -> dict[str, Any]:
    """The model's fields from a Pleiades / SPOT 6-7 DIMAP v2 RPC XML document (``RPC_*.XML``).

    ``Global_RFM/Inverse_Model`` (ground -> image) gives the projection polynomials and
    ``Global_RFM/Direct_Model`` (image -> ground; its SAMP_* coefficients give lon, its
    LINE_* give lat) the inverse. Offsets and scales come from ``RFM_Validity``. DIMAP pixel
    coordinates are 1-based: 1 is subtracted from ``SAMP_OFF`` and ``LINE_OFF``.
    """
    if not text or not text.strip():
        raise InputError("the DIMAP RPC XML is empty")
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise InputError(f"the DIMAP RPC XML cannot be parsed: {exc}") from None
    rfm = root if root.tag == "Global_RFM" else root.find(".//Global_RFM")
    if rfm is None:
        raise InputError("no <Global_RFM> element in the XML; is it a DIMAP v2 RPC file?")

    def section(tag: str) -> ET.Element:
        el = rfm.find(tag)
        if el is None:
            raise InputError(f"<{tag}> is missing from <Global_RFM>; give a complete RPC XML")
        return el

    def value(el: ET.Element, key: str) -> float:
        sub = el.find(key)
        if sub is None or sub.text is None:
            raise InputError(f"DIMAP RPC key {key!r} is missing from <{el.tag}>")
        return parse_number(key, sub.text)

    def coeffs(el: ET.Element, prefix: str) -> FloatArray:
        return np.array([value(el, f"{prefix}_{i}") for i in range(1, 21)])

    inv, direct, valid = section("Inverse_Model"), section("Direct_Model"), section("RFM_Validity")
    kw: dict[str, Any] = {name: value(valid, key) for name, key in GDAL_SCALARS.items()}
    kw["col_off"] -= 1.0
    kw["row_off"] -= 1.0
    for name, key in GDAL_COEFFS.items():
        kw[name] = coeffs(inv, key)
    kw["lon_num"] = coeffs(direct, "SAMP_NUM_COEFF")
    kw["lon_den"] = coeffs(direct, "SAMP_DEN_COEFF")
    kw["lat_num"] = coeffs(direct, "LINE_NUM_COEFF")
    kw["lat_den"] = coeffs(direct, "LINE_DEN_COEFF")
    return kw


def gdal_tags(scalars: Mapping[str, float], coeffs: Mapping[str, FloatArray]) -> dict[str, str]:
    """The GDAL RPC metadata domain of a model's offsets and scales (``scalars``, by field
    name) and forward coefficients (``coeffs``), numbers written exactly (``repr``)."""
    tags = {key: repr(float(scalars[name])) for name, key in GDAL_SCALARS.items()}
    for name, key in GDAL_COEFFS.items():
        tags[key] = " ".join(repr(float(v)) for v in coeffs[name])
    return tags

"""Read geoid grids (GTX) into :class:`core.geoid.GeoidGrid`; locate the bundled EGM96 grid."""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from core.errors import InputError
from core.geoid import GeoidGrid

DATA_DIR = Path(__file__).resolve().parents[1] / "data"
EGM96_GTX = DATA_DIR / "egm96_15.gtx"
BUNDLED_SRTM_DIR = DATA_DIR


def read_gtx(path: str | Path) -> GeoidGrid:
    """Read a GTX vertical grid: big-endian header ``>4d`` (lat0, lon0, dlat, dlon), ``>2i``
    (rows, cols), then rows*cols ``>f4`` values, row 0 at the south. -88.8888 marks no data."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read geoid grid {path}: {exc.strerror}; check the path") from exc
    if len(raw) < 40:
        raise InputError(f"geoid grid {path} is too short ({len(raw)} bytes) to be a GTX file")
    lat0, lon0, dlat, dlon = np.frombuffer(raw[:32], dtype=">f8")
    nrows, ncols = (int(v) for v in np.frombuffer(raw[32:40], dtype=">i4"))
    expected = 40 + 4 * nrows * ncols
    if nrows <= 0 or ncols <= 0 or len(raw) != expected:
        raise InputError(
            f"geoid grid {path} is malformed: header says {nrows}x{ncols} values "
            f"({expected} bytes) but the file has {len(raw)} bytes; use an intact GTX file"
        )
    values = np.frombuffer(raw[40:], dtype=">f4").astype(np.float64).reshape(nrows, ncols)
    values[np.abs(values + 88.8888) < 1e-3] = np.nan  # GTX no-data value
    lon0 = float(lon0)
    if lon0 >= 180.0:
        lon0 -= 360.0
    return GeoidGrid(values, float(lat0), lon0, float(dlat), float(dlon), name=path.name)


@functools.lru_cache(maxsize=4)
def load_geoid(path: str | None = None) -> GeoidGrid:
    """The geoid grid at ``path``, or the bundled EGM96 15' grid; cached per process."""
    return read_gtx(path if path is not None else EGM96_GTX)

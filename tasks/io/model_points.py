"""``gcpfree project`` and ``gcpfree localize``: ground points through a sensor model into image
coordinates, and image points at a height back to the ground, CSV in, CSV out.

Any model :func:`tasks.io.sensors.load_model` reads (a model file alone, or an image whose
model is found beside it: then ``col``/``row`` are that raster's pixels). Conventions as
everywhere in gcpfree: ``col``, ``row`` 0-based with pixel centres at integers; ``lon``, ``lat``
WGS84 degrees; ``h`` ellipsoidal metres. The output is the input, every column kept in order,
plus the new columns (``col,row`` or ``lon,lat``; overwritten in place when the input has
them) and, for a SAR model, the point's
``azimuth_time_utc`` (ISO 8601) and two-way ``slant_range_time_s`` (the corrections included).

Plain functions, no Prefect (as ``info``): a points file answers in about a second. Every input
is checked before anything is written; the output is written atomically.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Callable
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from core.sensors.sar import SarModel
from tasks.io.rasters import atomic_write_text
from tasks.io.sensors import load_model

PROJECT_IN = ("lon", "lat", "h")
LOCALIZE_IN = ("col", "row", "h")
SAR_COLUMNS = ("azimuth_time_utc", "slant_range_time_s")


def _read_points(path: Path, needed: tuple[str, ...]
                 ) -> tuple[list[str], list[list[str]], list[NDArray[np.float64]]]:
    """Header, rows and the needed columns as float arrays of a points CSV."""
    if not path.is_file():
        raise InputError(f"points file {path} does not exist; give a CSV with a header "
                         f"{','.join(needed)}")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read points file {path} ({type(exc).__name__}); give a UTF-8 "
                         "CSV") from None
    try:
        rows = [r for r in csv.reader(io.StringIO(text)) if any(c.strip() for c in r)]
    except csv.Error as exc:
        raise InputError(f"{path} is not a valid CSV ({exc})") from None
    if not rows:
        raise InputError(f"{path} is empty; give a CSV with a header {','.join(needed)}")
    header = [c.strip() for c in rows[0]]
    missing = [c for c in needed if c not in header]
    if missing:
        raise InputError(f"{path}: the header {','.join(header)[:80]!r} lacks "
                         f"{', '.join(missing)}; the columns needed are {','.join(needed)}")
    body = rows[1:]
    if not body:
        raise InputError(f"{path} has a header but no points")
    idx = [header.index(c) for c in needed]
    out = [np.empty(len(body)) for _ in needed]
    for i, r in enumerate(body):
        if len(r) != len(header):
            raise InputError(f"{path} line {i + 2}: {len(r)} fields, the header has "
                             f"{len(header)}")
        for k, j in enumerate(idx):
            try:
                v = float(r[j])
            except ValueError:
                v = float("nan")
            if not np.isfinite(v):
                raise InputError(f"{path} line {i + 2}: {needed[k]} = {r[j].strip()[:30]!r} is "
                                 "not a finite number")
            out[k][i] = v
    return header, body, out


def _fmt(values: NDArray[np.float64]) -> list[str]:
    return [repr(float(v)) for v in values]


def _write(path: Path, header: list[str], body: list[list[str]],
           added: dict[str, list[str]]) -> Path:
    """The input rows with the new columns: a column the input already has (``lon`` of a
    file that was projected before) is overwritten in place, the others are appended."""
    where = {c: header.index(c) for c in added if c in header}
    new = [c for c in added if c not in where]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header + new)
    for i, r in enumerate(body):
        r = list(r)
        for c, j in where.items():
            r[j] = added[c][i]
        w.writerow(r + [added[c][i] for c in new])
    try:
        return atomic_write_text(path, buf.getvalue())
    except OSError as exc:
        raise InputError(f"cannot write {path}: {exc.strerror}; choose another --out") from exc


def _check_out(out: Path, points: Path) -> None:
    parent = out.absolute().parent
    if out.is_dir() or not parent.is_dir():
        raise InputError(f"cannot write {out}: {parent} is not a folder (or the path is one); "
                         "choose another --out")
    if out.exists() and points.exists() and out.resolve() == points.resolve():
        raise InputError(f"--out {out} is the input points file; choose another path")


def _sar_columns(model: SarModel, t: NDArray[np.float64], tau: NDArray[np.float64]
                 ) -> dict[str, list[str]]:
    return {"azimuth_time_utc": model.utc_of_times(t), "slant_range_time_s": _fmt(tau)}


def _through_model(model: str | Path, points: str | Path, out: str | Path,
                   needed: tuple[str, ...], added: tuple[str, str],
                   convert: Callable[..., tuple[NDArray[np.float64], NDArray[np.float64]]],
                   sar_times: Callable[..., tuple[NDArray[np.float64], NDArray[np.float64]]]
                   ) -> Path:
    """The ``needed`` columns of ``points`` through the model: ``convert(model, a, b, h)``
    gives the two ``added`` columns, ``sar_times(model, a, b, h)`` a SAR model's (t, tau)."""
    points, out = Path(points), Path(out)
    _check_out(out, points)
    header, body, (a, b, h) = _read_points(points, needed)
    m = load_model(model).model
    x, y = convert(m, a, b, h)
    columns = {added[0]: _fmt(x), added[1]: _fmt(y)}
    if isinstance(m, SarModel):
        columns |= _sar_columns(m, *sar_times(m, a, b, h))
    return _write(out, header, body, columns)


def project_points(model: str | Path, points: str | Path, out: str | Path) -> Path:
    """Ground points (``lon,lat,h``) -> image (adds ``col,row``, and SAR times)."""
    return _through_model(model, points, out, PROJECT_IN, ("col", "row"),
                          lambda m, lon, lat, h: m.project(lon, lat, h),
                          lambda m, lon, lat, h: m.times(lon, lat, h))


def localize_points(model: str | Path, points: str | Path, out: str | Path) -> Path:
    """Image points at heights (``col,row,h``) -> ground (adds ``lon,lat``, and SAR times)."""
    return _through_model(model, points, out, LOCALIZE_IN, ("lon", "lat"),
                          lambda m, col, row, h: m.localize(col, row, h),
                          lambda m, col, row, h: m.times_of_image(col, row))

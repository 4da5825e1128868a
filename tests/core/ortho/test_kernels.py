"""The compiled ortho kernels of :mod:`core.ortho.kernels` against independent implementations:
scipy's ``map_coordinates(order=1)`` for the bilinear samplers (random data with voids,
positions on the edges, on integer nodes, just outside, NaN), a per-point Python loop for
nearest and cubic convolution, dense matrices and exact quadratics for the lattice
interpolation, and NumPy Horner for the image positions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.ndimage import map_coordinates

from core.ortho.kernels import (
    bilinear,
    cell_heights,
    footprint_bounds,
    image_position,
    to_integer,
    upsample,
)
from core.ortho.ortho import SourceWindow, _Axis, resample

# ---------------------------------------------------------------------------- helpers


def scipy_bilinear(z: np.ndarray, fi: np.ndarray, fj: np.ndarray) -> np.ndarray:
    """The reference: NaN outside [0, n - 1], else map_coordinates order 1."""
    z = np.asarray(z, dtype=np.float64)
    inside = (fi >= 0) & (fi <= z.shape[0] - 1) & (fj >= 0) & (fj <= z.shape[1] - 1)
    out = np.full(fi.shape, np.nan)
    out[inside] = map_coordinates(z, [fi[inside], fj[inside]], order=1, mode="nearest",
                                  prefilter=False)
    return out


def hard_positions(rng: np.random.Generator, n_r: int, n_c: int, n: int
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Random fractional positions plus integer nodes, the four edges exactly, a hair
    inside and outside them, and NaN."""
    fi = rng.uniform(-1.0, n_r, n)
    fj = rng.uniform(-1.0, n_c, n)
    k = n // 8
    fi[:k], fj[:k] = rng.integers(0, n_r, k), rng.integers(0, n_c, k)  # on nodes
    edges_i = np.array([0.0, n_r - 1.0, -1e-12, n_r - 1 + 1e-12, 1e-12, n_r - 1 - 1e-12])
    edges_j = np.array([0.0, n_c - 1.0, -1e-12, n_c - 1 + 1e-12, 1e-12, n_c - 1 - 1e-12])
    gi, gj = np.meshgrid(edges_i, np.r_[edges_j, 0.5 * n_c], indexing="ij")
    fi = np.r_[fi, gi.ravel(), np.nan, 3.0, np.nan]
    fj = np.r_[fj, gj.ravel(), 2.0, np.nan, np.nan]
    return fi, fj


# ---------------------------------------------------------------------------- bilinear


@pytest.mark.parametrize("dtype", [np.float64, np.float32, np.uint16])
def test_bilinear_equals_map_coordinates_with_voids_edges_and_nan(dtype):
    rng = np.random.default_rng(0)
    z = rng.uniform(0, 1000, (37, 53)).astype(dtype)
    if np.dtype(dtype).kind == "f":
        z[rng.uniform(size=z.shape) < 0.05] = np.nan  # voids, edges included
        z[0, 5] = z[36, 50] = np.nan
    fi, fj = hard_positions(rng, *z.shape, 20_000)
    got = bilinear(z, fi, fj)
    want = scipy_bilinear(z, fi, fj)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9, equal_nan=True)
    if np.dtype(dtype).kind == "f":  # voids spread to their neighbours, never further
        assert 0.05 < np.isnan(got).mean() < 0.5
    got2 = bilinear(z, fi.reshape(-1, 1)[:100], fj[:100].reshape(-1, 1))
    assert got2.shape == (100, 1)


# ---------------------------------------------------------------------------- resample


def reference_resample(window, win: SourceWindow, col, row, image_size, resampling, nodata):
    """One point at a time in Python: the window with its edges repeated, nodata as NaN."""
    src = np.asarray(window, dtype=np.float64).copy()
    if nodata is not None and not math.isnan(nodata):
        src[np.asarray(window) == nodata] = np.nan
    n_r, n_c = src.shape
    f = win.factor
    w, hgt = image_size

    def tap(i, j):
        return src[min(max(i, 0), n_r - 1), min(max(j, 0), n_c - 1)]

    def keys(t):
        return [0.5 * (-t ** 3 + 2 * t ** 2 - t), 0.5 * (3 * t ** 3 - 5 * t ** 2 + 2),
                0.5 * (-3 * t ** 3 + 4 * t ** 2 + t), 0.5 * (t ** 3 - t ** 2)]

    out = np.full(col.shape, np.nan)
    for k, (c, r) in enumerate(zip(col.ravel(), row.ravel(), strict=True)):
        if not (-0.5 <= c <= w - 0.5 and -0.5 <= r <= hgt - 0.5):
            continue
        lc = (c - win.col0 - 0.5 * (f - 1)) / f
        lr = (r - win.row0 - 0.5 * (f - 1)) / f
        if resampling == "nearest":
            v = tap(math.floor(lr + 0.5), math.floor(lc + 0.5))
        elif resampling == "bilinear":
            padded = np.pad(src, 2, mode="edge")
            v = scipy_bilinear(padded, np.array([lr + 2]), np.array([lc + 2]))[0]
        else:
            i0, j0 = math.floor(lr), math.floor(lc)
            wi, wj = keys(lr - i0), keys(lc - j0)
            v = sum(wi[a] * wj[b] * tap(i0 + a - 1, j0 + b - 1)
                    for a in range(4) for b in range(4))
        out.ravel()[k] = v
    return out


@pytest.mark.parametrize("resampling", ["nearest", "bilinear", "cubic"])
@pytest.mark.parametrize("factor", [1, 3])
def test_resample_equals_an_independent_implementation(resampling, factor):
    """A window inside a 120 x 90 image, with nodata pixels (at its edges too), positions
    over the whole footprint, its exact edges, a hair outside, on pixel centres, NaN."""
    rng = np.random.default_rng(factor)
    image_size = (120, 90)
    win = SourceWindow(col0=6, row0=3, n_cols=100 // factor, n_rows=80 // factor,
                       factor=factor)
    window = rng.integers(1, 4000, (win.n_rows, win.n_cols)).astype(np.uint16)
    window[rng.uniform(size=window.shape) < 0.03] = 0
    window[0, 2] = window[-1, -1] = window[5, 0] = 0
    n = 4000
    col = rng.uniform(-2, image_size[0] + 1, n)
    row = rng.uniform(-2, image_size[1] + 1, n)
    col[:400], row[:400] = rng.integers(0, 120, 400), rng.integers(0, 90, 400)
    ec = np.array([-0.5, -0.5 - 1e-9, -0.5 + 1e-9, 119.5, 119.5 + 1e-9, 119.5 - 1e-9, 40.0])
    er = np.array([-0.5, -0.5 - 1e-9, -0.5 + 1e-9, 89.5, 89.5 + 1e-9, 89.5 - 1e-9, 30.0])
    gc, gr = np.meshgrid(ec, er)
    col = np.r_[col, gc.ravel(), np.nan, 5.0].reshape(-1, 1)
    row = np.r_[row, gr.ravel(), 5.0, np.nan].reshape(-1, 1)
    got = resample(window, win, col, row, image_size, resampling, nodata=0)
    want = reference_resample(window, win, col, row, image_size, resampling, 0)
    assert got.shape == col.shape
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-8, equal_nan=True)
    assert 0.5 < np.isfinite(got).mean() < 0.95  # both values and holes were tested
    # no nodata: the zeros are values
    got = resample(window, win, col, row, image_size, resampling, nodata=None)
    want = reference_resample(window, win, col, row, image_size, resampling, None)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-8, equal_nan=True)


def test_resample_float_image_with_nan_nodata():
    rng = np.random.default_rng(4)
    window = rng.uniform(0, 1, (30, 40)).astype(np.float32)
    window[10, 10] = np.nan
    win = SourceWindow(0, 0, 40, 30)
    col, row = rng.uniform(0, 39, (50, 50)), rng.uniform(0, 29, (50, 50))
    col[0, 0], row[0, 0] = 10.4, 9.7  # next to the NaN pixel
    got = resample(window, win, col, row, (40, 30), "bilinear", nodata=float("nan"))
    want = reference_resample(window, win, col, row, (40, 30), "bilinear", None)
    assert np.isnan(got[0, 0])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9, equal_nan=True)


# ---------------------------------------------------------------------------- lattice


def dense(axis: _Axis) -> np.ndarray:
    """The axis' interpolation as a dense (n, n_nodes) matrix."""
    m = np.zeros((axis.n, axis.nodes.size))
    for a in range(4):
        np.add.at(m, (np.arange(axis.n), axis.taps[:, a]), axis.weights[:, a])
    return m


def test_upsample_is_the_separable_matrix_product_and_exact_on_quadratics():
    rows, cols = _Axis.make(70, 16), _Axis.make(45, 8)
    rng = np.random.default_rng(5)
    nodes = rng.normal(size=(3, rows.nodes.size, cols.nodes.size))
    got = upsample(nodes, rows.taps, rows.weights, cols.taps, cols.weights)
    want = np.einsum("ia,fab,jb->fij", dense(rows), nodes, dense(cols))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    # Keys' cubic convolution reproduces quadratics: node values of a quadratic give it back
    ni, nj = np.meshgrid(rows.nodes, cols.nodes, indexing="ij")
    quad = lambda i, j: 0.01 * i * i - 0.02 * i * j + 0.03 * j * j + i - 2 * j + 5
    got = upsample(quad(ni, nj)[None], rows.taps, rows.weights, cols.taps, cols.weights)[0]
    ci, cj = np.mgrid[0:70, 0:45].astype(float)
    np.testing.assert_allclose(got, quad(ci, cj), rtol=0, atol=1e-9)


@pytest.mark.parametrize("degree", [1, 2, 4])
def test_image_position_is_horner_on_the_upsampled_coefficients(degree):
    rows, cols = _Axis.make(50, 8), _Axis.make(33, 16)
    rng = np.random.default_rng(degree)
    coeffs = rng.normal(size=(2, degree + 1, rows.nodes.size, cols.nodes.size))
    h = rng.uniform(100, 900, (50, 33))
    h[3, 4] = np.nan
    col, row = image_position(coeffs, rows.taps, rows.weights, cols.taps, cols.weights, h,
                              500.0, 400.0)
    u = (h - 500.0) / 400.0
    for o, got in enumerate((col, row)):
        c = np.einsum("ia,kab,jb->kij", dense(rows), coeffs[o], dense(cols))
        want = sum(c[k] * u ** k for k in range(degree + 1))
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-9, equal_nan=True)
    assert np.isnan(col[3, 4]) and np.isnan(row[3, 4]) and np.isfinite(np.delete(col, 3 * 33 + 4)).all()


def test_cell_heights_are_the_dem_sampled_at_the_interpolated_indices():
    rows, cols = _Axis.make(60, 16), _Axis.make(40, 8)
    rng = np.random.default_rng(7)
    z = rng.uniform(100, 900, (30, 25)).astype(np.float32)
    z[rng.uniform(size=z.shape) < 0.05] = np.nan
    ni, nj = np.meshgrid(rows.nodes, cols.nodes, indexing="ij")
    # indices running over the DEM and past its edges (NaN there), a smooth undulation
    nodes = np.stack([0.5 * ni - 2.0 + 0.1 * nj, 0.6 * nj - 1.5, 40.0 + 0.01 * ni])
    h = cell_heights(nodes, rows.taps, rows.weights, cols.taps, cols.weights, z)
    # the indices as upsample gives them (tested above): the same bits decide which taps a
    # position near a node takes, so the voids spread identically
    fi, fj, n_m = upsample(nodes, rows.taps, rows.weights, cols.taps, cols.weights)
    want = scipy_bilinear(z, fi, fj) + n_m
    np.testing.assert_array_equal(np.isnan(h), np.isnan(want))
    np.testing.assert_allclose(h, want, rtol=0, atol=1e-9, equal_nan=True)
    assert 0.1 < np.isnan(h).mean() < 0.7


def test_footprint_bounds_of_the_positions_inside_the_image():
    rng = np.random.default_rng(8)
    col, row = rng.uniform(-5, 105, (40, 30)), rng.uniform(-5, 55, (40, 30))
    col[0, 0], row[1, 1] = np.nan, np.nan
    col[2, 2], row[2, 2] = -0.5, 49.5  # on the footprint's edges: inside
    n, c_lo, c_hi, r_lo, r_hi = footprint_bounds(col, row, (100, 50))
    with np.errstate(invalid="ignore"):
        inside = (col >= -0.5) & (col <= 99.5) & (row >= -0.5) & (row <= 49.5)
    assert n == inside.sum()
    assert (c_lo, c_hi, r_lo, r_hi) == (col[inside].min(), col[inside].max(),
                                        row[inside].min(), row[inside].max())
    assert footprint_bounds(col + 1000, row, (100, 50))[0] == 0


def numpy_to_integer(values, dtype, nodata):
    """The NumPy expression the kernel replaces."""
    info = np.iinfo(dtype)
    v = np.clip(np.rint(values), info.min, info.max)
    if nodata is not None and not math.isnan(nodata):
        v = np.where(v == nodata, nodata + (1 if nodata < info.max else -1), v)
        v = np.where(np.isnan(values), nodata, v)
    else:
        v = np.where(np.isnan(values), 0, v)
    return v.astype(dtype)


@pytest.mark.parametrize(("dtype", "nodata"), [("uint8", 0.0), ("uint8", 255.0), ("uint8", None),
                                               ("uint16", 0.0), ("int16", -9999.0),
                                               ("int16", float("nan"))])
def test_to_integer_rounds_clips_and_moves_values_off_nodata_as_numpy(dtype, nodata):
    rng = np.random.default_rng(9)
    info = np.iinfo(dtype)
    values = rng.uniform(info.min - 50.0, info.max + 50.0, 5000)
    values[:300] = rng.integers(-3, 300, 300) + 0.5  # ties round half to even
    values[300:400] = np.nan
    if nodata is not None and not math.isnan(nodata):
        values[400:450] = nodata + rng.uniform(-0.49, 0.49, 50)  # valid values at nodata
    got = to_integer(values.reshape(50, 100), np.dtype(dtype), nodata)
    assert got.dtype == np.dtype(dtype) and got.shape == (50, 100)
    np.testing.assert_array_equal(got.ravel(), numpy_to_integer(values, dtype, nodata))

"""A damaged LAZ never ends the process (issue 17, item 3), and damaged points are refused.

lazrs, laspy's LAZ decoder, does not always raise on damaged data: a damaged chunk table makes
it allocate tens of gigabytes and abort (SIGABRT), or panic (pyo3's ``PanicException``, a
``BaseException``). The files here are the real Autzen tile with one byte changed, found by
trying every single-byte change of the offset to its chunk table and of the table: the first
test proves each still crashes laspy when read in place, the others that gcpfree turns each
into one line naming the file, through ``tasks.io.lidar`` and through ``gcpfree evaluate``
(in this process, which survives, and as the installed command).

Damaged bytes that decode without error give wrong points: points outside the header's box and
of reserved classes are planted in sound files, counted exactly, left out and reported, and a
file with more than 1 in 10,000 of them is refused.
"""

from __future__ import annotations

import json
import os
import signal
import struct
import subprocess
import sys
from pathlib import Path

import laspy
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from core.errors import GcpFreeError, InputError
from core.evaluation.evaluation_report import MAX_REFUSED_SHARE, refused_points
from core.jsonio import to_json
from flows import cli
from tasks.evaluation.lidar import EvaluationOptions, evaluate_plan, plan_evaluation
from tasks.io import lidar as lidar_io
from tasks.io.lidar import inspect_lidar, lidar_chunks
from tasks.io.products import EVALUATION
from tests.tasks.test_evaluate import AUTZEN, write_las, write_raster

# (byte offset, XOR mask) in autzen_trim.laz (point data at byte 2144, chunk table at 603333)
ABORT_OFFSET = (2144, 0x02)  # the offset to the chunk table: a 40 GB allocation, SIGABRT
ABORT_TABLE = (603340, 0x80)  # the table's chunk count: a 34 GB allocation, SIGABRT
PANIC_TABLE = (603342, 0x02)  # an entry of the table: a panic in the second chunk
CRASHES = {"abort_offset": ABORT_OFFSET, "abort_table": ABORT_TABLE,
           "panic_table": PANIC_TABLE}

BARE_READ = """
import sys, laspy
with laspy.open(sys.argv[1]) as f:
    for _ in f.chunk_iterator(50_000):
        pass
"""


def _damaged(folder: Path, name: str, edit: tuple[int, int]) -> Path:
    data = bytearray(AUTZEN.read_bytes())
    data[edit[0]] ^= edit[1]
    path = folder / f"{name}.laz"
    path.write_bytes(bytes(data))
    return path


@pytest.fixture(scope="module")
def crashes(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("crashes")
    return {name: _damaged(d, name, edit) for name, edit in CRASHES.items()}


def _read(path: Path, n: int = 50_000) -> int:
    """What every command does with a lidar file: the header checked, the points streamed."""
    src = inspect_lidar(path)
    return sum(len(c) for c in lidar_chunks(path, n, src.info.point_count))


def _one_line(exc: BaseException, path: Path) -> str:
    msg = str(exc)
    assert "\n" not in msg and path.name in msg, msg
    return msg


# ---------------------------------------------------------------------------- the pinned crashes


@pytest.mark.parametrize("name", list(CRASHES))
def test_the_pinned_files_crash_laspy_in_place(crashes, name):
    """The regression the rest of this module guards against: laspy reading these files in its
    own process dies by SIGABRT or by an uncaught PanicException (with a Rust backtrace). If
    lazrs stops crashing on them, pin other files (search the chunk table as the docstring
    says) so the tests below keep testing a crash."""
    r = subprocess.run([sys.executable, "-c", BARE_READ, str(crashes[name])],
                       capture_output=True, text=True, timeout=120, check=False,
                       env={**os.environ, "RUST_BACKTRACE": "0"})
    if name.startswith("abort"):
        assert r.returncode == -signal.SIGABRT, (r.returncode, r.stderr[-500:])
        assert "memory allocation of" in r.stderr
    else:
        assert r.returncode == 1 and "PanicException" in r.stderr, (r.returncode, r.stderr[-500:])


@pytest.mark.parametrize("name", ["abort_offset", "abort_table"])
def test_an_aborting_decoder_is_one_input_error(crashes, name):
    with pytest.raises(InputError) as err:
        _read(crashes[name])
    msg = _one_line(err.value, crashes[name])
    assert "the LAZ decoder crashed reading its chunk table" in msg
    assert "killed by SIGABRT: memory allocation of" in msg


def test_a_panicking_decoder_is_one_input_error_after_the_points_read(crashes):
    path = crashes["panic_table"]
    assert inspect_lidar(path).info.point_count == 110_000  # the first chunk decodes
    with pytest.raises(InputError) as err:
        _read(path)
    msg = _one_line(err.value, path)
    assert "after 50000 of 110000 points (PanicException: " in msg  # lazrs's words vary


def test_a_crash_in_the_middle_of_the_stream(monkeypatch):
    """A child that aborts after its first chunk (tests/tasks/laz_abort_child.py): the chunk
    read comes through, then the crash is one InputError saying where it happened."""
    monkeypatch.setattr(lidar_io, "CHILD", "tests.tasks.laz_abort_child")
    got = []
    with pytest.raises(InputError) as err:
        for chunk in lidar_chunks(AUTZEN, 40_000, 110_000):
            got.append(len(chunk))
    assert got == [40_000]
    msg = _one_line(err.value, AUTZEN)
    assert "the LAZ decoder crashed after 40000 of 110000 points (killed by SIGABRT" in msg


def test_a_consumer_that_stops_early_ends_the_child(monkeypatch):
    """No child left running or unreaped when the stream is abandoned after one chunk."""
    started: list[subprocess.Popen] = []

    class Recorded(subprocess.Popen):
        def __init__(self, *a, **k):
            super().__init__(*a, **k)
            started.append(self)

    monkeypatch.setattr(lidar_io.subprocess, "Popen", Recorded)
    chunks = lidar_chunks(AUTZEN, 1000, 110_000)
    assert len(next(chunks)) == 1000
    chunks.close()
    assert len(started) == 1 and started[0].returncode is not None


def test_the_intact_file_reads_the_same_through_the_child():
    """The child's points are laspy's, bit for bit."""
    with laspy.open(AUTZEN) as f:
        ref = f.read()
    chunks = list(lidar_chunks(AUTZEN, 30_000, 110_000))
    assert [len(c) for c in chunks] == [30_000, 30_000, 30_000, 20_000]
    assert sum(c.refused_bounds + c.refused_class for c in chunks) == 0
    for name in ("x", "y", "z", "classification"):
        np.testing.assert_array_equal(np.concatenate([getattr(c, name) for c in chunks]),
                                      np.asarray(getattr(ref, name)))


# the offset to the chunk table and the table itself, where lazrs aborts or panics (a third of
# single-byte damages there crash it), in the 300-point seed of tests/test_bad_input.py
@settings(max_examples=25, deadline=None, database=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_damaged_chunk_tables_never_leak(tmp_path, data):
    seed = _small_laz(tmp_path)
    p0 = 2144  # as Autzen's: the same header and records
    table = int.from_bytes(seed[p0:p0 + 8], "little")
    where = st.one_of(st.integers(p0, p0 + 7), st.integers(table, len(seed) - 1))
    edits = data.draw(st.lists(st.tuples(where, st.integers(1, 255)), min_size=1, max_size=3))
    damaged = bytearray(seed)
    for i, x in edits:
        damaged[i] ^= x
    path = tmp_path / "damaged.laz"
    path.write_bytes(bytes(damaged))
    try:
        _read(path)
    except GcpFreeError as exc:
        _one_line(exc, path)


def _small_laz(tmp: Path) -> bytes:
    path = tmp / "seed.laz"
    if not path.exists():
        las = laspy.read(AUTZEN)
        las.points = las.points[:300]
        las.write(path)
    return path.read_bytes()


# ---------------------------------------------------------------------------- the command


@pytest.fixture(scope="module")
def autzen_dem(tmp_path_factory) -> Path:
    """A flat DEM in UTM 10N over the Autzen tile (ellipsoidal heights)."""
    d = tmp_path_factory.mktemp("autzen_dem")
    return write_raster(d / "dem.tif", np.full((20, 40), 130.0, np.float32), "EPSG:32610",
                        (10.0, 0, 494_100.0, 0, -10.0, 4_877_620.0),
                        tags={"vertical_datum": "WGS84 ellipsoid"})


def test_gcpfree_evaluate_on_an_aborting_laz_exits_2_and_this_process_survives(
        crashes, autzen_dem, tmp_path, capsys):
    out = tmp_path / "eval.json"
    code = cli.main(["evaluate", "--dem", str(autzen_dem), "--lidar",
                     str(crashes["abort_offset"]), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("gcpfree evaluate: error: lidar file ")
    assert "abort_offset.laz is corrupt: the LAZ decoder crashed" in err and "SIGABRT" in err
    assert not out.exists()


def test_gcpfree_evaluate_on_a_panicking_laz_exits_2(prefect_harness, crashes, autzen_dem,
                                                     tmp_path, capfd):
    """The panic comes in the second chunk, while the flow streams the points."""
    out = tmp_path / "eval.json"
    code = cli.main(["evaluate", "--dem", str(autzen_dem), "--lidar",
                     str(crashes["panic_table"]), "--out", str(out), "--chunk-points",
                     "50000"])
    err = capfd.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1, err
    assert "panic_table.laz is truncated or corrupt after 50000 of 110000 points" in err
    assert not out.exists()


def test_the_installed_gcpfree_on_an_aborting_laz(crashes, autzen_dem, tmp_path):
    exe = Path(sys.executable).with_name("gcpfree")
    r = subprocess.run([str(exe), "evaluate", "--dem", str(autzen_dem), "--lidar",
                        str(crashes["abort_table"]), "--out", str(tmp_path / "e.json")],
                       capture_output=True, text=True, timeout=300, check=False,
                       env={**os.environ, "PREFECT_HOME": str(tmp_path / "prefect")})
    assert r.returncode == 2, r.stderr
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and "abort_table.laz is corrupt: the LAZ decoder crashed" in lines[0]


# ---------------------------------------------------------------------------- refused points


def test_refused_points_box_slack_nan_and_classes():
    x = np.array([10.0, 10.0005, 10.0025, 5.0, 7.0, 7.0])
    y = np.full(6, 3.0)
    z = np.full(6, 1.0)
    codes = np.array([2, 2, 2, 2, 30, 64])
    box = {"mins": (5.0, 3.0, 1.0), "maxs": (10.0, 3.0, 1.0), "scales": (0.001,) * 3}
    outside, reserved = refused_points(x, y, z, codes, **box)
    # 10.0005: within one scale step; 10.0025: beyond it and the float32 rounding of 10
    assert outside.tolist() == [False, False, True, False, False, False]
    assert reserved.tolist() == [False, False, False, False, True, False]  # 64: user class
    _, reserved = refused_points(x, y, z, codes, **box, accept=(30,))
    assert not reserved.any()
    outside, _ = refused_points(x, y, z, codes, (5.0, np.nan, 1.0), (10.0, 3.0, 1.0),
                                (0.001,) * 3)
    assert outside.all()


X0, Y1 = 680_000.0, 4_896_000.0  # UTM 31N


def _planted(path: Path, n: int, n_out: int, n_reserved: int) -> tuple[Path, int]:
    """``n`` points on a 100 m square, ``n_out`` of them 5 m east of it and ``n_reserved`` of
    class 30; the header's max x then set to the square's edge (as damage would leave it)."""
    rng = np.random.default_rng(5)
    x = X0 + rng.uniform(1.0, 99.0, n)
    y = Y1 - rng.uniform(1.0, 99.0, n)
    z = 99.5 + rng.normal(0.0, 0.05, n)
    cls = np.full(n, 2)
    x[:n_out] = X0 + 105.0
    cls[n_out:n_out + n_reserved] = 30
    write_las(path, x, y, z, cls, None)
    data = bytearray(path.read_bytes())
    struct.pack_into("<d", data, 179, X0 + 100.0)  # LAS header: max x
    path.write_bytes(bytes(data))
    return path, n


@pytest.mark.parametrize("suffix", [".las", ".laz"])
def test_points_outside_the_box_and_of_reserved_classes_are_counted_and_left_out(tmp_path,
                                                                                 suffix):
    path, n = _planted(tmp_path / f"p{suffix}", 30_000, 2, 1)  # 3 = 0.01 % of 30,000
    chunks = list(lidar_chunks(path, 7000, n))
    assert sum(c.refused_bounds for c in chunks) == 2
    assert sum(c.refused_class for c in chunks) == 1
    assert sum(len(c) for c in chunks) == n - 3
    assert max(float(c.x.max()) for c in chunks) < X0 + 100.0
    accepted = list(lidar_chunks(path, 7000, n, accept_classes=(30,)))
    assert sum(c.refused_class for c in accepted) == 0


@pytest.mark.parametrize("suffix", [".las", ".laz"])
def test_a_file_with_more_refused_points_is_refused(tmp_path, suffix):
    n = 30_000
    k = int(MAX_REFUSED_SHARE * n) + 1
    path, _ = _planted(tmp_path / f"p{suffix}", n, k, 0)
    with pytest.raises(InputError) as err:
        list(lidar_chunks(path, 7000, n))
    msg = _one_line(err.value, path)
    assert f"{k} points read lie outside its header's box" in msg
    assert "more than 0.01 % of its 30000 points" in msg


def test_reserved_classes_are_left_out_but_do_not_condemn_a_file(tmp_path):
    """National products use reserved classes (AHN's 26): their points are left out of the
    evaluation and counted, but only points outside the box, which a sound file never has,
    refuse the file."""
    n = 30_000
    k = int(MAX_REFUSED_SHARE * n) + 50
    path, _ = _planted(tmp_path / "p.laz", n, 0, k)
    chunks = list(lidar_chunks(path, 7000, n))
    assert sum(c.refused_class for c in chunks) == k and sum(len(c.x) for c in chunks) == n - k


def test_a_header_box_that_is_not_finite_is_refused(tmp_path):
    path, _ = _planted(tmp_path / "p.laz", 1000, 0, 0)
    data = bytearray(path.read_bytes())
    struct.pack_into("<d", data, 187, float("nan"))  # min x
    path.write_bytes(bytes(data))
    with pytest.raises(InputError, match="corrupt header: its box"):
        inspect_lidar(path, crs="EPSG:32631")


def test_the_evaluation_reports_the_refused_share(tmp_path, capsys):
    dem = write_raster(tmp_path / "dem.tif", np.full((60, 60), 100.0, np.float32),
                       "EPSG:32631", (2.0, 0, X0, 0, -2.0, Y1),
                       tags={"vertical_datum": "WGS84 ellipsoid"})
    path, n = _planted(tmp_path / "p.laz", 30_000, 1, 1)
    report = evaluate_plan(plan_evaluation(EvaluationOptions(
        dem=dem, lidar=path, lidar_crs="EPSG:32631", lidar_vertical="ellipsoidal",
        chunk_points=5000)))
    p = report.points
    assert (p.read, p.refused_bounds, p.refused_class, p.evaluated) == (n, 1, 1, n - 2)
    assert p.read == (p.refused + p.withheld + p.excluded_class + p.outside_dem + p.on_void
                      + p.evaluated)
    d = EVALUATION.dump(report)
    assert d["points"]["refused_pct"] == pytest.approx(100 * 2 / n)
    err = capsys.readouterr().err.splitlines()
    assert err == [(f"lidar file {path}: 1 of {n} points (0.003 %) left out, outside the "
                    "header's box: the file is damaged"),
                   (f"lidar file {path}: 1 points of reserved classes 23..63 left out (name "
                    "them with --classes to evaluate them)")]
    # an eval.json written before the refused counts existed still reads
    for key in ("refused_bounds", "refused_class", "refused_pct"):
        del d["points"][key]
    assert EVALUATION.load(json.loads(to_json(d))).points.refused == 0

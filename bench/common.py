"""What the benchmarks and the validation studies share: running ``gcpfree`` on a simulated
scene, reading what it wrote, and the check-point figures the studies report.

- :func:`cli`, :func:`simulate`, :func:`orient`: the commands as a user runs them, each in a
  child process (its own temporary Prefect server), in a :func:`workspace` (a temporary folder,
  or ``--keep DIR`` where a scene or an orientation already there is reused);
- :func:`read_report`, :func:`worst_check_rms`, :func:`lens_decision`: ``report.json``;
- :func:`beyond_shift` (and :func:`line` to print it): per image, the check points as measured,
  beyond the reference's drawn shift and beyond the used GCPs' common error, beside the RMS the
  report predicts (issue 19);
- :func:`orient_and_measure`: an orientation and its :func:`beyond_shift`, the row of the
  studies' tables;
- :func:`solution_again`: an orientation run again in this process from its products, with the
  product's public estimator (:func:`core.orientation.adjust.adjust`).

The scripts import it as ``bench.common`` (the repository's root on ``sys.path``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

if TYPE_CHECKING:
    from core.orientation.adjust import AdjustConfig, ControlSet, ImageToAdjust, Solution
    from core.orientation.ties import TieObservations
#: the simulator's error models (``gcpfree simulate --errors``)
ERRORS = ("realistic", "simple")


# ---------------------------------------------------------------------------- running gcpfree


def load() -> str:
    """The 1, 5 and 15 minute load averages: figures taken on shared cores say it."""
    one, five, fifteen = os.getloadavg()
    return f"load {one:.1f} {five:.1f} {fifteen:.1f}"


@contextmanager
def workspace(keep: Path | None = None, prefix: str = "gcpfree-bench-"
              ) -> Iterator[tuple[Path, dict[str, str]]]:
    """A folder for scenes and products (``keep``, kept and reused, or a temporary one removed
    at the end) and the environment of the commands run there (their own ``PREFECT_HOME``)."""
    with tempfile.TemporaryDirectory(prefix=prefix) as tmp:
        root = Path(keep) if keep is not None else Path(tmp)
        root.mkdir(parents=True, exist_ok=True)
        yield root, dict(os.environ, PREFECT_HOME=str(root / "prefect"),
                         PREFECT_SERVER_ANALYTICS_ENABLED="false")


def cli(args: Sequence[str], env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    """``gcpfree ARGS`` in a child process (stdout and stderr captured)."""
    return subprocess.run([sys.executable, "-m", "flows.cli", *args], capture_output=True,
                          text=True, env=env, cwd=REPO, check=False)


def refusal(r: subprocess.CompletedProcess[str]) -> str:
    """The last line a failed command wrote on stderr (its one-line refusal)."""
    return (r.stderr.strip().splitlines() or ["?"])[-1]


def simulate(scene: Path, env: dict[str, str], preset: str, seed: int | str,
             *options: str) -> str | None:
    """``gcpfree simulate --preset PRESET --seed SEED OPTIONS --out SCENE`` unless ``scene``
    already holds a simulated scene (its check points); the refusal, or None when done."""
    if (scene / "truth" / "checkpoints.json").is_file():
        return None
    r = cli(["simulate", "--preset", preset, "--seed", str(seed), *options, "--out",
             str(scene)], env)
    return refusal(r) if r.returncode else None


def given_or_simulated(given: Path | None, tmp: Path, env: dict[str, str], preset: str,
                       seed: int, *options: str) -> Path:
    """A benchmark's scene: the folder ``given`` (checked: a ``gcpfree simulate`` output), or
    one simulated into ``tmp/PRESET`` (``gcpfree simulate --preset PRESET --seed SEED
    OPTIONS``; reused when already there)."""
    if given is not None:
        if not (given / "left.tif").is_file() or not (given / "reference.tif").is_file():
            raise SystemExit(f"{given} holds no left.tif and reference.tif: give a folder "
                             "written by gcpfree simulate")
        return given
    scene = tmp / preset
    t0 = time.perf_counter()
    refused = simulate(scene, env, preset, seed, *options)
    if refused is not None:
        raise SystemExit(f"gcpfree simulate --preset {preset}: {refused}")
    print(f"scene {scene} (--preset {preset} --seed {seed} {' '.join(options)}) in "
          f"{time.perf_counter() - t0:.0f} s; {load()}", flush=True)
    return scene


def orient(scene: Path, out: Path, env: dict[str, str], *options: str
           ) -> tuple[float, str | None]:
    """``gcpfree orient --self-calibrate`` of the simulated ``scene`` (no GCP, its reference,
    its check points) into ``out`` with ``options``: (seconds, the refusal or None)."""
    t0 = time.perf_counter()
    r = cli(["orient", "--left", str(scene / "left.tif"), "--right", str(scene / "right.tif"),
             "--reference", str(scene / "reference.tif"), "--checkpoints",
             str(scene / "truth" / "checkpoints.json"), "--self-calibrate", "--no-progress",
             *options, "--out", str(out)], env)
    return time.perf_counter() - t0, (refusal(r) if r.returncode else None)


def pair_args(scene: Path, out: Path, workers: int) -> list[str]:
    """``gcpfree pair`` on the simulated ``scene`` as the benchmarks time it: its reference and
    check points, lens self-calibration, the truth lidar and land cover when the scene has them,
    ``workers`` workers."""
    truth = scene / "truth"
    lidar = (["--lidar", str(truth / "lidar.laz"), "--landcover", str(truth / "landcover.tif")]
             if (truth / "lidar.laz").exists() else [])
    return ["pair", "--left", str(scene / "left.tif"), "--right", str(scene / "right.tif"),
            "--reference", str(scene / "reference.tif"), "--checkpoints",
            str(truth / "checkpoints.json"), "--self-calibrate", *lidar, "--workers",
            str(workers), "--no-progress", "--out", str(out)]


def read_report(out: Path) -> dict[str, Any]:
    """An orientation's ``report.json``."""
    return json.loads((out / "report.json").read_text())


def worst_check_rms(report: dict[str, Any]) -> float:
    """The worst check-point RMS of a report (px, the larger axis of the worse image)."""
    return max(max(c["rms_col_px"], c["rms_row_px"]) for c in report["check_points"].values())


def lens_decision(report: dict[str, Any]) -> Any:
    """The lens self-calibration's decision in a report (None without it)."""
    return (report["absolute"].get("self_calibration") or {}).get("decision")


def reference_shift_m(scene: Path) -> list[float]:
    """The simulated reference's drawn misregistration (east, north; m)."""
    err = json.loads((scene / "truth" / "reference_errors.json").read_text())
    return [err["shift_east_m"], err["shift_north_m"]]


@dataclass(frozen=True)
class Comparison:
    """One speed figure against a peer measured in the same run: what was timed, the peer,
    both times (s, the same work on the same data)."""

    what: str
    peer: str
    gcpfree_s: float
    peer_s: float

    @property
    def ratio(self) -> float:
        """gcpfree's time over the peer's (below 1: gcpfree is faster)."""
        return self.gcpfree_s / self.peer_s


def write_comparisons(path: Path | None, bench: str, rows: Sequence[Comparison]) -> None:
    """A benchmark's comparisons as JSON at ``path`` (nothing when None), with the load."""
    if path is None:
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"bench": bench, "load": load(), "comparisons": [
        {**asdict(r), "ratio": r.ratio} for r in rows]}, indent=1))


def place(text: str) -> tuple[str, str, str]:
    """A ``SEED:LON:LAT`` option (a tiny scene's seed and centre), checked."""
    parts = text.split(":")
    try:
        if len(parts) != 3:
            raise ValueError
        int(parts[0]), float(parts[1]), float(parts[2])
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give SEED:LON:LAT, e.g. 1:5.75:44.75"
                                         ) from None
    return parts[0], parts[1], parts[2]


def write_results(path: Path, doc: Any) -> None:
    """A study's figures as JSON (what ``bench/results/`` keeps and the docs read)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc, indent=1))
    print(f"figures written to {path}")


# ---------------------------------------------------------------------------- check points


def _rms(v: np.ndarray) -> float:
    return float(np.sqrt(np.mean(v**2)))


def gcp_common_error(scene: Path, out: Path) -> tuple[float, float, float]:
    """The used GCPs' mean error (east, north, up; m) against the truth: each GCP's image
    points triangulated with the scene's true models give its true ground."""
    from core.geodesy import metres_per_degree
    from core.intersection import triangulate
    from tasks.absolute.orientation import NAMES
    from tasks.io.sensors import read_model_file

    rep = read_report(out)
    rejected = {r["id"] for r in rep["gcps"]["rejected_ids"]}
    pts = [p for p in json.loads((out / "gcps.json").read_text())["points"]
           if p["id"] not in rejected]
    models = [read_model_file(scene / "truth" / f"{n}_truth.json").model for n in NAMES]
    cols = [np.array([p["images"][n]["col"] for p in pts]) for n in NAMES]
    rows = [np.array([p["images"][n]["row"] for p in pts]) for n in NAMES]
    lon, lat, h = (np.array([p[k] for p in pts]) for k in ("lon_deg", "lat_deg", "h_m"))
    t = triangulate(models, cols, rows, (float(h.min()) - 500.0, float(h.max()) + 500.0))
    m_lon, m_lat = metres_per_degree(lat)
    return (float(np.mean((lon - t.lon_deg) * m_lon)), float(np.mean((lat - t.lat_deg) * m_lat)),
            float(np.mean(h - t.h_m)))


def carried(truth: Any, lon: np.ndarray, lat: np.ndarray, h: np.ndarray,
            e: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """What a common ground error ``e`` (east, north, up; m) of the GCPs leaves in check points'
    residuals: the adjusted model takes X + e to the image of X, so a check point at X computes
    the image of X - e and its residual holds truth(X) - truth(X - e)."""
    from core.geodesy import metres_per_degree

    m_lon, m_lat = metres_per_degree(lat)
    tc, tr = truth.project(lon, lat, h)
    sc, sr = truth.project(lon - e[0] / m_lon, lat - e[1] / m_lat, h - e[2])
    return tc - sc, tr - sr


def check_point_arrays(scene: Path, name: str) -> tuple[np.ndarray, ...]:
    """lon, lat, h, col, row of the scene's check points measured in image ``name``."""
    from tasks.absolute.orientation import read_checkpoints

    points = read_checkpoints(scene / "truth" / "checkpoints.json")
    pts = [p for p in points.points if name in p.image_points]
    return tuple(np.array(v, dtype=float) for v in zip(
        *[(p.lon_deg, p.lat_deg, p.h_m, p.image_points[name].col, p.image_points[name].row)
          for p in pts], strict=True))


def beyond_shift(scene: Path, out: Path) -> dict[str, dict[str, Any]]:
    """Per image: ``rms_col_px``/``rms_row_px`` measured, ``beyond_col_px``/``beyond_row_px``
    once the reference's drawn shift (through the true models) is out of every residual,
    ``beyond_common_col_px``/``beyond_common_row_px`` once the used GCPs' mean error against
    the truth (``gcp_common_error_m``: the shift, the canopy share the reference sees, its
    tilt, all common to the GCPs) is,
    ``predicted_col_px``/``predicted_row_px`` as report.json states them and
    ``predicted_beyond_col_px``/``predicted_beyond_row_px`` without their reference term (the
    reference's stated registration sigma through the ground's partial derivatives)."""
    from core.orientation.uncertainty import ground_jacobian, predicted_rms_px
    from tasks.absolute.orientation import NAMES
    from tasks.io.sensors import read_model_file

    rep = read_report(out)
    shift = reference_shift_m(scene)
    sigma = np.asarray(rep["settings"]["absolute"]["reference_sigma_m"], dtype=float)
    common = gcp_common_error(scene, out)
    res: dict[str, dict[str, Any]] = {}
    for name in NAMES:
        lon, lat, h, col, row = check_point_arrays(scene, name)
        model = read_model_file(out / f"{name}.json").model
        truth = read_model_file(scene / "truth" / f"{name}_truth.json").model
        pc, pr = model.project(lon, lat, h)
        dc, dr = col - pc, row - pr
        # the GCPs sit where the reference shows the terrain, moved by its shift
        shc, shr = carried(truth, lon, lat, h, (shift[0], shift[1], 0.0))
        bc, br = dc - shc, dr - shr
        cmc, cmr = carried(truth, lon, lat, h, common)
        gc, gr = dc - cmc, dr - cmr
        cp = rep["check_points"][name]
        ref_c, ref_r = predicted_rms_px(ground_jacobian(model, lon, lat, h), np.diag(sigma**2))
        res[name] = {
            "rms_col_px": _rms(dc), "rms_row_px": _rms(dr),
            "shift_col_px": _rms(shc), "shift_row_px": _rms(shr),
            "beyond_col_px": _rms(bc), "beyond_row_px": _rms(br),
            "beyond_mean_col_px": float(np.mean(bc)), "beyond_mean_row_px": float(np.mean(br)),
            "gcp_common_error_m": list(common),
            "beyond_common_col_px": _rms(gc), "beyond_common_row_px": _rms(gr),
            "predicted_col_px": cp["predicted_rms_col_px"],
            "predicted_row_px": cp["predicted_rms_row_px"],
            "predicted_beyond_col_px": float(np.sqrt(max(
                cp["predicted_rms_col_px"] ** 2 - ref_c**2, 0.0))),
            "predicted_beyond_row_px": float(np.sqrt(max(
                cp["predicted_rms_row_px"] ** 2 - ref_r**2, 0.0)))}
    return res


def line(name: str, r: dict[str, Any]) -> str:
    """One image's figures of :func:`beyond_shift` (col / row, px), as printed."""
    return (f"{name:5s} measured {r['rms_col_px']:.2f} / {r['rms_row_px']:.2f}, the shift "
            f"{r['shift_col_px']:.2f} / {r['shift_row_px']:.2f}, beyond it "
            f"{r['beyond_col_px']:.2f} / {r['beyond_row_px']:.2f} (mean "
            f"{r['beyond_mean_col_px']:+.2f} / {r['beyond_mean_row_px']:+.2f}), beyond the "
            f"GCPs' common error ({', '.join(f'{x:+.1f}' for x in r['gcp_common_error_m'])} "
            f"m) {r['beyond_common_col_px']:.2f} / {r['beyond_common_row_px']:.2f}; predicted "
            f"{r['predicted_col_px']:.2f} / {r['predicted_row_px']:.2f}, without the "
            f"reference {r['predicted_beyond_col_px']:.2f} / "
            f"{r['predicted_beyond_row_px']:.2f}; ratio beyond the common error "
            f"{r['beyond_common_col_px'] / r['predicted_beyond_col_px']:.2f} / "
            f"{r['beyond_common_row_px'] / r['predicted_beyond_row_px']:.2f}")


def orient_and_measure(scene: Path, out: Path, env: dict[str, str], *options: str
                       ) -> dict[str, Any]:
    """:func:`orient` of the simulated ``scene`` into ``out`` (not run again when ``out`` holds
    a report) with ``options``, and its check points as :func:`beyond_shift` measures them:
    ``seconds`` (when run), ``refused`` (the error's last line) or ``reference_shift_m`` and
    ``images``."""
    row: dict[str, Any] = {}
    if not (out / "report.json").is_file():
        row["seconds"], refused = orient(scene, out, env, *options)
        if refused is not None:
            return {**row, "refused": refused}
    row["reference_shift_m"] = reference_shift_m(scene)
    row["images"] = beyond_shift(scene, out)
    return row


# ---------------------------------------------------------------------------- the solution again


@dataclass(frozen=True, eq=False)
class OrientationInputs:
    """What an SRTM-only ``gcpfree orient`` gave its estimator, read back from its products:
    the images (the left as delivered, the right as the relative orientation left it), the
    surface-matching GCPs in the reference's frame, the tie points and the settings."""

    images: tuple[ImageToAdjust, ...]
    control: tuple[ControlSet, ...]
    ties: TieObservations | None
    config: AdjustConfig


def orientation_inputs(scene: Path, out: Path) -> OrientationInputs:
    """:class:`OrientationInputs` of the orientation in ``out`` of the simulated ``scene``."""
    from core.orientation.absolute import AbsoluteConfig
    from core.orientation.adjust import AdjustConfig, ControlSet, ImageToAdjust
    from core.orientation.frames import REFERENCE, FramePrior
    from core.sensors.pushbroom import PushbroomModel
    from tasks.absolute.orientation import tie_observations
    from tasks.absolute.surface_match import TieGround
    from tasks.io.products import GCPS
    from tasks.io.sensors import load_model

    s = read_report(out)["settings"]
    absolute = AbsoluteConfig(**{k: tuple(v) if isinstance(v, list) else v
                                 for k, v in s["absolute"].items()})
    left = load_model(scene / "left.tif")
    rel = json.loads((out / "relative" / "rel.json").read_text())
    right = replace(load_model(scene / "right.tif"),
                    model=PushbroomModel.from_dict(rel["right_model"]))
    gcps = GCPS.read(out / "gcps.json").points
    ties = TieGround.from_tiepoints_json(out / "relative" / "rel.tiepoints.json")
    control = (ControlSet("surface", gcps, FramePrior(REFERENCE, absolute.reference_sigma_m)),)
    config = AdjustConfig(absolute=absolute, corrections=s["corrections"],
                          lens=s["self_calibrate"], along_track=s["along_track"])
    images = tuple(ImageToAdjust(n, m.model, m.size) for n, m in (("left", left),
                                                                  ("right", right)))
    return OrientationInputs(images, control, tie_observations(ties, absolute), config)


def solution_again(scene: Path, out: Path) -> Solution:
    """The orientation of ``out`` run again from its GCPs, tie points and settings
    (deterministic: the solution ``gcpfree orient`` wrote)."""
    from core.orientation.adjust import adjust

    inp = orientation_inputs(scene, out)
    return adjust(inp.images, inp.control, inp.ties, inp.config)

"""GCP-free orientation against a reference made without the simulator's reference code
(issue 19: "held-out terrain and references made independently of the simulator's").

The simulator's ``reference.tif`` and the chain were written by the same hands: a defect shared
by both (a half-cell convention, a noise spectrum the matching happens to suit) would not
show. Here the reference is made from the scene's truth with nothing of ``core.simulation``:
the truth DTM plus ``CANOPY`` of the canopy and building height the truth DSM adds (C band sees
part of it; one share for the scene, not per stand), averaged over 90 m (an odd box: an even
one moves the surface half a cell), sampled on the simulator reference's 3" lattice at
positions moved by ``SHIFT_M`` (at an azimuth drawn from the seed), plus white noise
Gaussian-filtered to a correlation of about ``CORR_M`` and scaled to ``NOISE_M``; no voids,
no tilt. The same scene is oriented against both references (``gcpfree orient
--self-calibrate``, no GCP) and measured at its check points (``beyond_shift.py``: as
measured, beyond the reference's shift, beyond the used GCPs' common error).

GCPFREE_INDEPENDENT_CASES: ``seed:lon:lat`` items of the ``tiny`` preset (``--lens``,
realistic errors), comma separated (default three of the uncertainty sweep's);
GCPFREE_INDEPENDENT_SCENES: existing simulated scene folders to use as well (a ``spot``
scene: about 4 minutes per orientation); GCPFREE_INDEPENDENT_CANOPY / _SHIFT_M / _NOISE_M /
_CORR_M (default 0.5, 8, 4, 600); GCPFREE_INDEPENDENT_KEEP=DIR keeps everything there (and
reuses what is there). Writes independent_reference.json into GCPFREE_INDEPENDENT_OUT (default
the current folder). Prints figures, asserts nothing.
"""

from __future__ import annotations

import json
import os
import tempfile
import zlib
from pathlib import Path

import numpy as np
import rasterio
from beyond_shift import line
from pyproj import Transformer
from realistic_table import oriented
from relief_sweep import cli
from scipy.ndimage import gaussian_filter, map_coordinates, uniform_filter

DEFAULT = "1:5.75:44.75,3:5.25:44.2,6:5.45:44.15"
CASES = [c.split(":") for c in os.environ.get("GCPFREE_INDEPENDENT_CASES", DEFAULT).split(",")
         if c]
SCENES = [Path(p) for p in os.environ.get("GCPFREE_INDEPENDENT_SCENES", "").split(",") if p]
CANOPY = float(os.environ.get("GCPFREE_INDEPENDENT_CANOPY", "0.5"))
SHIFT_M = float(os.environ.get("GCPFREE_INDEPENDENT_SHIFT_M", "8"))
NOISE_M = float(os.environ.get("GCPFREE_INDEPENDENT_NOISE_M", "4"))
CORR_M = float(os.environ.get("GCPFREE_INDEPENDENT_CORR_M", "600"))
#: the footprint SRTM's 3" heights average over (m)
FOOTPRINT_M = 90.0


def make_reference(scene: Path, dest: Path, seed: int) -> tuple[float, float]:
    """Write ``dest`` on the lattice of ``scene/reference.tif`` from ``scene/truth``; return
    the shift (east, north, m): the reference shows the world moved by it."""
    rng = np.random.default_rng(seed)
    azimuth = rng.uniform(0.0, 2.0 * np.pi)
    dx, dy = SHIFT_M * np.sin(azimuth), SHIFT_M * np.cos(azimuth)
    with rasterio.open(scene / "reference.tif") as r:
        profile, tr, shape, tags = r.profile, r.transform, r.shape, r.tags()
    with rasterio.open(scene / "truth" / "dtm.tif") as d:
        dtm, ttr, crs = d.read(1).astype(np.float64), d.transform, d.crs
    with rasterio.open(scene / "truth" / "dsm.tif") as d:
        dsm = d.read(1).astype(np.float64)
    box = int(round(FOOTPRINT_M / ttr.a)) | 1
    surface = uniform_filter(dtm + CANOPY * (dsm - dtm), size=box, mode="nearest")
    rows, cols = np.mgrid[0:shape[0], 0:shape[1]]
    lon, lat = tr.c + (cols + 0.5) * tr.a, tr.f + (rows + 0.5) * tr.e
    x, y = Transformer.from_crs(4326, crs, always_xy=True).transform(lon, lat)
    h = map_coordinates(surface, [(y - dy - ttr.f) / ttr.e - 0.5, (x - dx - ttr.c) / ttr.a - 0.5],
                        order=1, cval=np.nan)
    noise = gaussian_filter(rng.normal(size=shape), CORR_M / (abs(tr.e) * 111_320.0))
    h = h + NOISE_M * noise / noise.std()
    profile.update(dtype="float32", nodata=np.nan)
    tmp = dest.with_suffix(".part.tif")
    with rasterio.open(tmp, "w", **profile) as out:
        out.write(h.astype(np.float32), 1)
        out.update_tags(**{**tags, "source": "bench/validation/independent_reference.py"})
    tmp.replace(dest)
    return float(dx), float(dy)


def independent_scene(scene: Path, dest: Path, seed: int) -> Path:
    """``dest``: ``scene`` with links to its images and truth, its own reference and its
    own ``truth/reference_errors.json`` (the shift, what ``beyond_shift`` takes out)."""
    (dest / "truth").mkdir(parents=True, exist_ok=True)
    for src in [*scene.iterdir(), *(scene / "truth").iterdir()]:
        if src.name in ("reference.tif", "reference_errors.json", "truth", "work"):
            continue
        link = dest / src.relative_to(scene)
        if not link.exists():
            link.symlink_to(src.resolve())
    if not (dest / "reference.tif").is_file():
        dx, dy = make_reference(scene, dest / "reference.tif", seed)
        (dest / "truth" / "reference_errors.json").write_text(json.dumps({
            "shift_east_m": dx, "shift_north_m": dy, "canopy_seen": CANOPY, "noise_m": NOISE_M,
            "correlation_m": CORR_M, "source": "bench/validation/independent_reference.py"}, indent=1))
    return dest


def orient(scene: Path, out: Path, env: dict[str, str]) -> dict:
    """:func:`realistic_table.oriented`, with the lens decision of the report."""
    row = oriented(scene, out, env)
    if "images" in row:
        rep = json.loads((out / "report.json").read_text())
        row["lens"] = (rep["absolute"].get("self_calibration") or {}).get("decision")
    return row


def main() -> None:
    dest = Path(os.environ.get("GCPFREE_INDEPENDENT_OUT", "."))
    keep = os.environ.get("GCPFREE_INDEPENDENT_KEEP")
    rows = []
    with tempfile.TemporaryDirectory() as tmp_dir:
        tmp = Path(keep or tmp_dir)
        env = dict(os.environ, PREFECT_HOME=str(tmp / "prefect"))
        scenes = list(SCENES)
        for seed, lon, lat in CASES:
            scene = tmp / f"tiny_{seed}"
            if not (scene / "truth" / "checkpoints.json").is_file():
                r = cli(["simulate", "--preset", "tiny", "--seed", seed, "--center", lon, lat,
                         "--lens", "--errors", "realistic", "--no-lidar", "--out", str(scene)],
                        env)
                if r.returncode:
                    rows.append({"scene": scene.name, "refused": r.stderr.strip()[-300:]})
                    continue
            scenes.append(scene)
        for scene in scenes:  # the draws follow the scene's name, not the order
            indep = independent_scene(scene, tmp / f"{scene.name}_independent",
                                      zlib.crc32(scene.name.encode()))
            row = {"scene": scene.name,
                   "simulator": orient(scene, tmp / f"orient_{scene.name}", env),
                   "independent": orient(indep, tmp / f"orient_{indep.name}", env)}
            rows.append(row)
            for kind in ("simulator", "independent"):
                r = row[kind]
                print(f"{scene.name}, {kind} reference: shift "
                      f"{r.get('reference_shift_m')}, lens: {r.get('lens')}")
                for name, img in r.get("images", {}).items():
                    print("  " + line(name, img))
    settings = {"canopy": CANOPY, "shift_m": SHIFT_M, "noise_m": NOISE_M, "corr_m": CORR_M}
    (dest / "independent_reference.json").write_text(
        json.dumps({"settings": settings, "scenes": rows}, indent=1))


if __name__ == "__main__":
    main()

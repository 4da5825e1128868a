"""The block's products beside its models: each image's orientation exported as an RPC other
tools read (a GDAL VRT over the image with the RPC in its metadata, and gcpfree's RPC file),
and report.json (:class:`BlockReport`, written through :mod:`tasks.io.documents`)."""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from xml.sax.saxutils import escape

from rasterio.errors import NotGeoreferencedWarning

from core.orientation.adjust import Solution
from core.sensors.base import SensorModel
from core.sensors.rpcfit import fit_rpc
from tasks.io.documents import Document
from tasks.io.model_files import model_document
from tasks.io.rasters import atomic_write_json, atomic_write_text, open_raster

BLOCK_FORMAT = "gcpfree.block"


def export_rpc(model: SensorModel, image: Path, size: tuple[int, int],
               h_range_m: tuple[float, float], out: Path) -> dict[str, Any]:
    """The oriented ``model`` fitted as an RPC00B over the image and heights (margin 100 m),
    written as ``out.rpc.json`` (gcpfree) and ``out.vrt``, a GDAL VRT of ``image`` carrying it
    in its RPC metadata domain (``gdalwarp -rpc``, rasterio's ``rpcs``, CARS, ASP read it);
    the fit's errors on an independent grid (px)."""
    h0, h1 = float(h_range_m[0]) - 100.0, float(h_range_m[1]) + 100.0
    rpc, report = fit_rpc(model, int(size[0]), int(size[1]), (h0, h1))
    atomic_write_json(out.with_suffix(".rpc.json"), model_document(rpc))
    with warnings.catch_warnings():  # an image in sensor geometry: no georeferencing
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        with open_raster(image, "image", "give the block's image") as src:
            dtype, bands = src.dtypes[0], src.count
    gdal_type = {"uint8": "Byte", "uint16": "UInt16", "int16": "Int16", "float32": "Float32",
                 "uint32": "UInt32", "int32": "Int32", "float64": "Float64"}[dtype]
    items = "".join(f'    <MDI key="{k}">{escape(str(v))}</MDI>\n'
                    for k, v in rpc.to_gdal_tags().items())
    bands_xml = "".join(
        f'  <VRTRasterBand dataType="{gdal_type}" band="{b}">\n'
        f'    <SimpleSource><SourceFilename relativeToVRT="0">{escape(str(Path(image).resolve()))}'
        f'</SourceFilename><SourceBand>{b}</SourceBand></SimpleSource>\n'
        "  </VRTRasterBand>\n" for b in range(1, bands + 1))
    atomic_write_text(out.with_suffix(".vrt"), (
        f'<VRTDataset rasterXSize="{int(size[0])}" rasterYSize="{int(size[1])}">\n'
        f'  <Metadata domain="RPC">\n{items}  </Metadata>\n{bands_xml}</VRTDataset>\n'))
    return {"rpc": out.with_suffix(".rpc.json").name, "vrt": out.with_suffix(".vrt").name,
            "fit_rms_px": report.rms_px, "fit_max_px": report.max_px,
            "heights_m": [h0, h1]}


@dataclass(frozen=True, kw_only=True)
class BlockImage:
    """One image of the block: its name, files, how it is held (``gcps``: it measures GCPs;
    ``ties``: only through tie points to its neighbours), its GCPs kept, its residuals there
    and its tie points, the RPC export, and the RMS predicted over it (total, relative to the
    frames, the frames' registration; col / row px)."""

    name: str
    image: str
    model: str
    held_by: str
    gcps: int
    residual_rms_px: tuple[float | None, float | None]
    tie_points: int
    rpc_export: Mapping[str, Any]
    predicted: Mapping[str, Any]


@dataclass(frozen=True, kw_only=True)
class BlockPair:
    """One stereo pair: its id, images, B/H, the relief verdict on its windows, their counts,
    the GCPs it gave (0 when refused: its images are then held by tie points) and its DSM."""

    id: str
    images: tuple[str, str]
    b_over_h: float
    verdict: Mapping[str, Any]
    windows: Mapping[str, int]
    gcps: int
    dsm: str


@dataclass(frozen=True, kw_only=True)
class BlockReport:
    """``OUT/report.json`` of ``gcpfree block``."""

    format: str = BLOCK_FORMAT
    version: int = 1
    images: tuple[BlockImage, ...]
    pairs: tuple[BlockPair, ...]
    connectivity: Mapping[str, Any]
    frames: tuple[Mapping[str, Any], ...]
    gcps: Mapping[str, Any]
    tie_points: Mapping[str, Any]
    adjustment: Mapping[str, Any]
    self_calibration: Mapping[str, Any] | None = None
    dsm: Mapping[str, Any] = field(default_factory=dict)
    reference: Mapping[str, Any] = field(default_factory=dict)
    check_points: Mapping[str, Mapping[str, Any]] | None = None
    check_points_before: Mapping[str, Mapping[str, Any]] | None = None
    settings: Mapping[str, Any] = field(default_factory=dict)

    def lines(self) -> list[str]:
        """The block's figures as ``gcpfree block`` prints them."""
        g, t = self.gcps, self.tie_points
        rms = t.get("rms_px")
        out = [(f"block                 {len(self.images)} images, {len(self.pairs)} stereo "
                f"pairs; {g['used']} GCPs used of {g['given']}, {t['n']} tie points"
                + (f" (parallax {rms:.3f} px RMS)" if rms is not None else ""))]
        for p in self.pairs:
            why = "" if p.gcps else f": none, {p.verdict.get('reason') or 'no window matched'}"
            out.append(f"pair {p.id:<16} B/H {p.b_over_h:.2f}, {p.gcps} GCPs{why}")
        for im in self.images:
            c = (self.check_points or {}).get(im.name)
            cps = "" if c is None else (f"; check points P {c['rms_col_px']:.3f} L "
                                        f"{c['rms_row_px']:.3f} px ({c['n']}), predicted "
                                        f"{c['predicted_rms_col_px']:.3f} / "
                                        f"{c['predicted_rms_row_px']:.3f}")
            out.append(f"image {im.name:<15} held by {im.held_by}, {im.gcps} GCPs, "
                       f"{im.tie_points} tie points{cps}")
        d = self.dsm
        if d:
            out.append(f"fused DSM             {d.get('dem_path')} "
                       f"({d.get('completeness_pct', float('nan')):.1f} % complete), views in "
                       f"{d.get('views_path')}")
        return out


BLOCK: Document[BlockReport] = Document("block report.json", BlockReport, format=BLOCK_FORMAT,
                                        hint="give the report.json written by gcpfree block")


def block_images(solution: Solution, files: Mapping[str, tuple[str, str]],
                 exports: Mapping[str, Mapping[str, Any]]) -> tuple[BlockImage, ...]:
    """Each image's line of report.json from the solution (``files``: name -> image, model
    file written)."""
    conn = solution.connectivity
    ties_only = set(conn.ties_only) if conn is not None else set()
    predicted = solution.predicted_over_images()["images"]
    n_ties = {n: sum(k for a, b, k in (conn.links if conn else ()) if n in (a, b))
              for n in solution.names}
    out = []
    for k, name in enumerate(solution.names):
        r = solution.adjustment.residuals[k]
        out.append(BlockImage(
            name=name, image=files[name][0], model=files[name][1],
            held_by="ties" if name in ties_only else "gcps", gcps=r.n,
            residual_rms_px=(r.rms_col_px if r.n else None, r.rms_row_px if r.n else None),
            tie_points=n_ties[name], rpc_export=exports.get(name, {}),
            predicted={key: v for key, v in predicted[name].items()
                       if key.startswith("predicted")}))
    return tuple(out)

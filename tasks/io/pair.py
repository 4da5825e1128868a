"""The inputs of a stereo pair, as one value: both images, their model files, the SPOT band,
and the reference DEM with its vertical datum (or the DEM tiles to prepare it from, and the
geoid their heights refer to).

Every command that takes a pair (``relative``, ``dsm``, ``orient``, ``pair``) builds one
:class:`PairInputs` from its options (:meth:`PairInputs.from_args`), the archive one per
catalog entry, and the flows and tasks pass it whole.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

from core.choices import TIE_MEASURES, VERTICAL_CHOICES, TieMeasure, VerticalChoice
from core.errors import InputError

PATHS = ("left", "right", "left_model", "right_model", "reference", "srtm_dir", "geoid")


@dataclass(frozen=True)
class PairInputs:
    """A stereo pair's files (see ``gcpfree orient --help``).

    ``left`` stays fixed in the relative orientation, ``right`` is adjusted to it; each model
    is found beside its image unless ``left_model`` / ``right_model`` name it; ``band``: the
    SPOT band whose look angles to use (default the first). The ground: ``reference``, a DEM
    in EPSG:4326 whose heights ``reference_vertical`` says (``auto``: decided by the one datum
    rule), or ``srtm_dir``, the DEM a reference is prepared from over the pair (a folder of
    tiles, ``--dem-dir`` or ``--srtm-dir``: SRTM, NASADEM, Copernicus...); at most one of them.
    ``geoid``: the grid their orthometric heights refer to when not EGM96 (``--geoid``); a
    ``reference`` given with a ``geoid`` is prepared through it like tiles (it moves to
    ``srtm_dir``, so every step reads the ellipsoidal reference made from it).
    ``tie_measure``: how the tie points are correlated, ``auto`` (orientation correlation when
    the two images' suns differ, :func:`core.matching.tiepoints.choose_measure`), ``ncc`` or
    ``orientation``.
    """

    left: Path
    right: Path
    left_model: Path | None = None
    right_model: Path | None = None
    band: int | None = None
    reference: Path | None = None
    reference_vertical: VerticalChoice = "auto"
    srtm_dir: Path | None = None
    tie_measure: TieMeasure = "auto"
    geoid: Path | None = None

    def __post_init__(self) -> None:
        for name in PATHS:
            value = getattr(self, name)
            if value is not None and not isinstance(value, Path):
                object.__setattr__(self, name, Path(value))
        if self.reference is not None and self.srtm_dir is not None:
            raise InputError("give the reference DEM (--reference) or the DEM tiles to "
                             "prepare it from (--dem-dir, --srtm-dir), not both")
        if self.geoid is not None and self.reference is not None:
            if self.reference_vertical == "ellipsoidal":
                raise InputError("--reference-vertical ellipsoidal says the reference's "
                                 "heights need no geoid: drop --geoid")
            # prepared through the geoid over the pair, as tiles are
            object.__setattr__(self, "srtm_dir", self.reference)
            object.__setattr__(self, "reference", None)
        if self.reference_vertical not in VERTICAL_CHOICES:
            raise InputError(f"--reference-vertical {self.reference_vertical!r} unknown; use "
                             f"one of {', '.join(VERTICAL_CHOICES)}")
        if self.tie_measure not in TIE_MEASURES:
            raise InputError(f"--tie-measure {self.tie_measure!r} unknown; use one of "
                             f"{', '.join(TIE_MEASURES)}")

    @classmethod
    def from_args(cls, args: Any) -> PairInputs:
        """From a command's options (``--left --right --left-model --right-model --band
        --reference --reference-vertical --dem-dir/--srtm-dir --geoid --tie-measure``; those a
        command lacks stay unset)."""
        return cls(**{k: getattr(args, k) for k in
                      ("left", "right", "left_model", "right_model", "band", "reference",
                       "reference_vertical", "srtm_dir", "tie_measure", "geoid")
                      if getattr(args, k, None) is not None})

    @property
    def has_ground(self) -> bool:
        """Whether a reference is given or can be prepared (GCP-free orientation needs one)."""
        return self.reference is not None or self.srtm_dir is not None

    @property
    def dem_source(self):  # -> tasks.io.dem_tiles.DemSource
        """What the reference is prepared from (``srtm_dir``, with ``reference_vertical`` and
        ``geoid``), for :func:`tasks.io.reference.locate_tiles`; None with a reference given."""
        from tasks.io.dem_tiles import DemSource

        if self.srtm_dir is None:
            return None
        return DemSource(self.srtm_dir, self.reference_vertical, self.geoid)

    def load(self):  # -> tuple[LoadedModel, LoadedModel]
        """The sensor models of both images (:func:`tasks.io.sensors.load_model`)."""
        from tasks.io.sensors import load_model

        return (load_model(self.left, model=self.left_model, band=self.band),
                load_model(self.right, model=self.right_model, band=self.band))

    def with_models(self, left_model: Path, right_model: Path) -> PairInputs:
        """The same images with other model files (e.g. the oriented ``left.json``)."""
        return replace(self, left_model=Path(left_model), right_model=Path(right_model))

    def to_dict(self) -> dict[str, Any]:
        """JSON values (paths as strings), one key per field."""
        return {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(self).items()}

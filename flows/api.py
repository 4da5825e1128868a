"""The Python API: gcpfree's flows called from a notebook or a script, each returning the typed
result its flow returns (never a dict)::

    from flows import api

    scene = api.simulate("work/scene", seed=1, center=(5.75, 44.75), lens=True)
    oriented = api.orient_pair("work/scene/left.tif", "work/scene/right.tif", "work/orient",
                               reference="work/scene/reference.tif",
                               checkpoints="work/scene/truth/checkpoints.json",
                               self_calibrate=True)
    oriented.report.check_points["left"].rms_col_px    # OrientOutcome -> OrientReport
    dem = api.evaluate("work/orient/dsm.tif", "work/scene/truth/lidar.laz")
    dem.all.le68_m                                      # EvaluationReport

**Arguments.** Each function takes its flow's inputs as arguments and keywords, its options
by the names every other way of running gcpfree uses (:mod:`flows.options`: the columns of an
archive's catalog, ``pair.json``'s ``params``, the commands' options with ``_`` for ``-``:
``self_calibrate=True``, ``corrections="offset"``, ``min_windows=6``; the dotted ones of the
configs in ``options={"surface.radius_m": 3000}``). Paths may be strings. A bad value raises
the :class:`core.errors.GcpFreeError` the command would print in one line (InputError naming
the option, InsufficientReliefError for terrain too flat...). :func:`run` takes a flow's
parameter object itself (:class:`OrientParams`, :class:`PairParams`, :class:`DsmParams`,
:class:`EvaluationOptions`, :class:`SimulationParams`).

**Two ways to run** (``prefect=``), measured on the tiny simulated pair (``orient_pair`` with
check points, 600 x 600 px; 2 cores under a load of 11-18, so CPU seconds, wall in brackets):

- ``prefect=False`` (the default): plain Python calls, no Prefect API and no server. Every
  Prefect task and flow of the chain runs as its own function (:func:`plain_calls`).
  28-30 CPU-s (54-90 s). A task or flow called outside a flow run, even through ``flow.fn``,
  otherwise makes Prefect start its temporary API server first: the pinned Prefect 3.8 has no
  local mode (PrefectHQ/prefect#15927); a bare task waited 7-33 s for it here. What is lost:
  nothing is recorded (no flow or task runs, logs or artifacts on a dashboard), no Prefect
  retries (only the archive's I/O tasks, the STAC and evaluation writers have any), Prefect
  does not validate the flows' parameters (the parameter objects check themselves), and
  ``.submit``/``.map`` cannot run (the archive needs ``prefect=True``). What is gained: the
  seconds and the memory of the server, and the flows' lines printed straight into the
  notebook.
- ``prefect=True``: Prefect flow runs, as ``gcpfree COMMAND`` makes them. Against a server
  (``PREFECT_API_URL`` or a profile: ``prefect server start``): 31 CPU-s (84 s), the runs,
  their logs and artifacts on its dashboard. Without one, Prefect's own temporary server,
  started in the first call of the Python process and kept until it ends: 42 CPU-s (83 s +
  the server's start) for the first call, its runs kept in ``PREFECT_HOME``'s database (a
  dashboard started later shows them).

:func:`block` orients a block of a ``gcpfree scenes`` catalog as ``gcpfree block`` does.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import threading
import typing
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any, TypeVar

from flows._env import configure_environment

configure_environment()  # offline, quiet defaults (what the user set wins): before Prefect

from core.errors import InputError
from core.evaluation.evaluation import StatsConfig
from core.evaluation.evaluation_report import EvaluationReport
from core.matching.surface import SurfaceMatchConfig
from core.orientation.absolute import AbsoluteConfig
from flows.block import BlockOutcome, BlockParams
from flows.dsm import DsmParams
from flows.options import NOT_OPTIONS, OPTIONS, PAIR_OPTIONS, with_options
from flows.orient import OrientOutcome, OrientParams
from flows.pair import PairOutcome, PairParams
from flows.simulate_scene import SimulationParams
from tasks.absolute.report import OrientReport, read_report
from tasks.dense.dem import DemSummary
from tasks.dense.multiview import ViewsDemSummary
from tasks.evaluation.lidar import EvaluationOptions
from tasks.io.pair import PairInputs
from tasks.simulate.scene import SimulationSummary

__all__ = [
    "OPTIONS", "AbsoluteConfig", "DemSummary", "DsmParams", "EvaluationOptions",
    "EvaluationReport", "OrientOutcome", "OrientParams", "OrientReport", "PairInputs",
    "PairOutcome", "PairParams", "SimulationParams", "SimulationSummary", "StatsConfig",
    "SurfaceMatchConfig", "ViewsDemSummary", "block", "dsm", "evaluate", "orient_pair",
    "plain_calls", "process_pair", "read_report", "run", "simulate",
]

R = TypeVar("R")
PathLike = str | os.PathLike[str]
#: the artifact functions a flow may call, made no-ops by :func:`plain_calls` (no API to hold
#: them)
ARTIFACTS = ("create_link_artifact", "create_markdown_artifact", "create_progress_artifact",
             "create_table_artifact", "create_image_artifact", "update_progress_artifact")


# ----------------------------------------------------------------------------- running


_PLAIN = threading.RLock()
_saved: dict[tuple[Any, str], Any] = {}  # what plain_calls replaced, while it lasts
_depth = 0


def _prefect_only(self: Any, *args: Any, **kwargs: Any) -> Any:
    raise InputError(f"{getattr(self, 'name', self)} fans out over Prefect's task runner "
                     "(.submit/.map), which only a Prefect flow run has: call it with "
                     "prefect=True")


def _no_artifact(*args: Any, **kwargs: Any) -> None:
    return None


def _as_function(self: Any, *args: Any, return_state: bool = False, wait_for: Any = None,
                 **kwargs: Any) -> Any:
    if return_state:
        raise InputError(f"{self.name}: return_state needs a Prefect run; call it with "
                         "prefect=True")
    return self.fn(*args, **kwargs)


@contextlib.contextmanager
def plain_calls() -> Iterator[None]:
    """Within: every Prefect task and flow called runs as its undecorated function (its
    ``.fn``) and Prefect's artifact functions do nothing, so that no Prefect API, and no
    temporary server, is needed; ``.submit`` and ``.map`` raise InputError (they need a flow
    run's task runner). Process-wide while it lasts (one plain call at a time: another thread
    waits); re-entrant."""
    global _depth
    import prefect.artifacts
    from prefect.flows import Flow
    from prefect.tasks import Task

    plain = {(Task, "__call__"): _as_function, (Task, "submit"): _prefect_only,
             (Task, "map"): _prefect_only, (Flow, "__call__"): _as_function,
             **{(prefect.artifacts, name): _no_artifact for name in ARTIFACTS}}
    with _PLAIN:
        if _depth == 0:
            _saved.update({(owner, name): getattr(owner, name) for owner, name in plain})
            for (owner, name), new in plain.items():
                setattr(owner, name, new)
        _depth += 1
        try:
            yield
        finally:
            _depth -= 1
            if _depth == 0:
                for (owner, name), old in _saved.items():
                    setattr(owner, name, old)
                _saved.clear()


def run(params: Any, *, prefect: bool = False) -> Any:
    """The flow of a parameter object run on it, plainly or as a Prefect flow run (see the
    module docstring): :class:`OrientParams` -> :class:`OrientOutcome`, :class:`PairParams` ->
    :class:`PairOutcome`, :class:`BlockParams` -> :class:`BlockOutcome`,
    :class:`DsmParams` -> :class:`DemSummary` (or
    :class:`ViewsDemSummary`), :class:`EvaluationOptions` -> :class:`EvaluationReport`,
    :class:`SimulationParams` -> :class:`SimulationSummary`."""
    from flows.block import block_flow
    from flows.dsm import dsm_flow
    from flows.evaluate import evaluate_flow
    from flows.orient import orient_flow
    from flows.pair import pair_flow
    from flows.simulate_scene import simulate_scene

    flows: dict[type, Callable[[Any], Any]] = {
        OrientParams: orient_flow, PairParams: pair_flow, DsmParams: dsm_flow,
        BlockParams: block_flow,
        EvaluationOptions: evaluate_flow, SimulationParams: simulate_scene}
    chosen = flows.get(type(params))
    if chosen is None:
        names = ", ".join(t.__name__ for t in flows)
        raise InputError(f"api.run takes the parameters of a flow ({names}), not a "
                         f"{type(params).__name__}")
    if prefect:
        return chosen(params)
    with plain_calls():
        return chosen(params)


# ----------------------------------------------------------------------------- parameters


def _fields(cls: type) -> set[str]:
    return {f.name for f in dataclasses.fields(cls)}


def _params(cls: type[R], values: Mapping[str, Any], what: str) -> R:
    """``cls(**values)`` with the strings of its path fields made paths; an unknown field is
    an InputError naming the known ones."""
    unknown = sorted(set(values) - _fields(cls))
    if unknown:
        raise InputError(f"{what}: unknown argument(s) {', '.join(unknown)}; give "
                         f"{', '.join(sorted(_fields(cls)))}")
    hints = typing.get_type_hints(cls)
    return cls(**{k: Path(v) if isinstance(v, (str, os.PathLike)) and _is_path(hints[k])
                  else v for k, v in values.items()})


def _is_path(hint: Any) -> bool:
    return hint is Path or Path in typing.get_args(hint)


def _take(given: dict[str, Any], names: set[str]) -> dict[str, Any]:
    """The items of ``given`` named in ``names``, removed from it."""
    return {k: given.pop(k) for k in list(given) if k in names}


def _orient(left: PathLike, right: PathLike, out: PathLike, reference: PathLike | None,
            dem_dir: PathLike | None, progress: bool, given: dict[str, Any],
            what: str) -> OrientParams:
    """The :class:`OrientParams` of the pair's files (``left_model``, ``right_model``,
    ``reference_vertical``, ``geoid``: :class:`PairInputs`' fields) and the orientation's
    (``checkpoints``, ``sar``, ``sar_model``, ``workers``, ``write_report``), taken out of
    ``given``; what it leaves there are options."""
    pair_files = _take(given, _fields(PairInputs) - set(PAIR_OPTIONS))
    orient_files = _take(given, _fields(OrientParams) & NOT_OPTIONS)
    pair = _params(PairInputs, {"left": left, "right": right, "reference": reference,
                                "srtm_dir": dem_dir, **pair_files}, what)
    return _params(OrientParams, {"pair": pair, "out": out, "progress": progress,
                                  **orient_files}, what)


# ----------------------------------------------------------------------------- the flows


def simulate(out: PathLike, *, prefect: bool = False, **given: Any) -> SimulationSummary:
    """A SPOT-like stereo pair with known truth over a DEM (``gcpfree simulate``) into
    ``out``; ``given``: the fields of :class:`SimulationParams` (``preset``, ``seed``,
    ``center``, ``lens``, ``jitter``, ``date_change``, ``relief_factor``, ``lidar``,
    ``sar``...). Returns the flow's :class:`SimulationSummary` (``.lines()`` prints it)."""
    return run(_params(SimulationParams, {"out": out, **given}, "api.simulate"),
               prefect=prefect)


def orient_pair(left: PathLike, right: PathLike, out: PathLike, *,
                reference: PathLike | None = None, dem_dir: PathLike | None = None,
                prefect: bool = False, progress: bool = False,
                options: Mapping[str, Any] | None = None, **given: Any) -> OrientOutcome:
    """A stereo pair oriented without GCPs (``gcpfree orient``: relative orientation,
    relative DEM, SRTM surface matching, absolute orientation, final DSM) into ``out``.

    The ground: ``reference`` (a DEM in EPSG:4326) or ``dem_dir`` (a folder of SRTM,
    NASADEM or Copernicus tiles). ``given``: the pair's other files (``left_model``,
    ``right_model``, ``reference_vertical``, ``geoid``), the orientation's (``checkpoints``,
    ``sar``, ``sar_model``, ``workers``, ``write_report``) and its options by name
    (``self_calibrate=True``, ``corrections="offset"``; the dotted ones in ``options``:
    ``options={"surface.radius_m": 3000}``). Returns the flow's :class:`OrientOutcome`: its
    ``report`` (:class:`OrientReport`, what ``report.json`` holds) and ``report_path``.

    Raises:
        InsufficientReliefError: the terrain is too flat for surface matching.
        InputError: a bad input or option, said as the command says it.
    """
    given = dict(given)
    params = _orient(left, right, out, reference, dem_dir, progress, given, "api.orient_pair")
    return run(with_options(params, {**(options or {}), **given}, "api.orient_pair"),
               prefect=prefect)


def process_pair(left: PathLike, right: PathLike, out: PathLike, *,
                 reference: PathLike | None = None, dem_dir: PathLike | None = None,
                 lidar: PathLike | None = None, landcover: PathLike | None = None,
                 prefect: bool = False, progress: bool = False,
                 options: Mapping[str, Any] | None = None, **given: Any) -> PairOutcome:
    """The whole chain for a pair (``gcpfree pair``: the orientation, orthos, their check,
    the DSM against ``lidar`` per ``landcover`` class, the report, the STAC catalog,
    ``pair.json``) into ``out``, resuming at the first product missing; arguments as
    :func:`orient_pair`'s, with the chain's ``pair_id`` and options (``lidar_vertical``).
    Returns the flow's :class:`PairOutcome`. With ``prefect=False`` no artifact is made."""
    given = dict(given)
    orient = _orient(left, right, out, reference, dem_dir, progress, given,
                     "api.process_pair")
    params = _params(PairParams, {"orient": orient, "lidar": lidar, "landcover": landcover,
                                  **_take(given, {"pair_id"})}, "api.process_pair")
    return run(with_options(params, {**(options or {}), **given}, "api.process_pair"),
               prefect=prefect)


def dsm(left: PathLike, right: PathLike, out: PathLike, *, reference: PathLike | None = None,
        dem_dir: PathLike | None = None, prefect: bool = False, progress: bool = False,
        **given: Any) -> DemSummary | ViewsDemSummary:
    """The pair's DSM by dense matching (``gcpfree dsm``) into the GeoTIFF ``out``; ``given``:
    the pair's files (:class:`PairInputs`' fields) and the fields of :class:`DsmParams`
    (``orient``, ``resolution_m``, ``vertical``, ``roi``, ``images`` for N views...). Returns
    the flow's :class:`DemSummary` (:class:`ViewsDemSummary` with ``images``)."""
    pair = _params(PairInputs, {"left": left, "right": right, "reference": reference,
                                "srtm_dir": dem_dir, **_take(given, _fields(PairInputs))},
                   "api.dsm")
    return run(_params(DsmParams, {"pair": pair, "out": out, "progress": progress, **given},
                       "api.dsm"), prefect=prefect)


def evaluate(dem: PathLike, lidar: PathLike, out: PathLike | None = None, *,
             prefect: bool = False, **given: Any) -> EvaluationReport:
    """A DEM against lidar, per class (``gcpfree evaluate``); ``eval.json`` written when
    ``out`` is given; ``given``: the fields of :class:`EvaluationOptions` (``landcover``,
    ``classes``, ``mask``, ``gcps``, ``lidar_crs``, ``stats``...). Returns the flow's
    :class:`EvaluationReport` (``.all.le68_m``, ``.classes``)."""
    return run(_params(EvaluationOptions, {"dem": dem, "lidar": lidar, "out": out, **given},
                       "api.evaluate"), prefect=prefect)


def block(catalog: PathLike, out: PathLike, *, reference: PathLike | None = None,
          dem_dir: PathLike | None = None, block: str | None = None, prefect: bool = False,
          progress: bool = False, options: Mapping[str, Any] | None = None,
          **given: Any) -> BlockOutcome:
    """Every overlapping image of a block of ``catalog`` (``gcpfree scenes``; ``block``: its
    id, default the first) oriented in one adjustment into ``out`` (``gcpfree block``: tie
    points of every overlapping pair, each stereo pair's GCPs, one adjustment, the pairs'
    and the fused DSMs, orthos, RPC exports). ``given``: ``checkpoints`` (keyed by image
    name), ``workers`` and the orientation's options by name, as :func:`orient_pair`.
    Returns the flow's :class:`BlockOutcome` (``report``: :class:`BlockReport`)."""
    from tasks.block.control import select_block

    chosen = select_block(Path(catalog), block)
    given = {"left_model": chosen.models[0], "right_model": chosen.models[1], **given}
    params = _orient(chosen.images[0], chosen.images[1], out, reference, dem_dir, progress,
                     given, "api.block")  # takes the files out of given: options are left
    params = with_options(params, {**(options or {}), **given}, "api.block")
    return run(BlockParams(Path(catalog), params, block), prefect=prefect)

"""``--reference-sigma`` of ``gcpfree orient`` and ``gcpfree pair`` reaches the absolute
orientation and report.json's prediction; bad values are refused in one line (exit 2); the
prediction the orientation writes holds against check points when the GCPs' ground errors are
correlated, as a reference DEM's are."""

from __future__ import annotations

import argparse
import contextlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from core.errors import InputError
from core.geodesy import metres_per_degree
from core.orientation.ground_field import CorrelatedGroundError
from core.points import ControlPoint, ImagePoint
from flows import cli
from flows.commands import orient as orient_command
from flows.commands import pair as pair_command
from tasks.absolute.orientation import orient_absolute
from tasks.io.pair import PairInputs
from tasks.io.sensors import LoadedModel
from tests.core.orientation.test_absolute import check, models


def parse(command, *argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="gcpfree")
    command.add_parser(parser.add_subparsers(dest="command"))
    return parser.parse_args([command.__name__.rsplit(".", 1)[-1], *argv])


@dataclass
class Outcome:
    def lines(self) -> list[str]:
        return []


class Reached(Exception):
    pass


@pytest.fixture
def no_server(monkeypatch, tmp_path):
    """The commands' checks of the files and Prefect server stubbed (in a scratch folder):
    what reaches the flow is captured."""
    import flows._env
    import flows.commands._pair
    import flows.orient
    import flows.pair

    class Api:
        def ready(self) -> None:
            pass

    seen = {"real_pair_flow": flows.pair.pair_flow}
    monkeypatch.setattr(flows._env, "prefect_api", lambda: contextlib.nullcontext(Api()))
    monkeypatch.chdir(tmp_path)
    # both commands check the pair through orient's orient_params
    monkeypatch.setattr(orient_command, "check_pair", lambda args: (
        PairInputs(Path("l.tif"), Path("r.tif"), reference=Path("ref.tif")), None, None))
    monkeypatch.setattr(flows.commands._pair, "_check_scene_size", lambda *a: None)

    def orient_flow(params):
        seen["orient"] = params
        raise Reached

    def pair_flow(params):
        seen["pair"] = params
        return Outcome()

    monkeypatch.setattr(flows.orient, "orient_flow", orient_flow)
    monkeypatch.setattr(flows.pair, "pair_flow", pair_flow)
    return seen


PAIR = ("--left", "l.tif", "--right", "r.tif", "--reference", "ref.tif", "--out", "o")


def test_reference_sigma_reaches_the_absolute_configuration(no_server, monkeypatch):
    with pytest.raises(Reached):
        orient_command.run(parse(orient_command, *PAIR, "--reference-sigma", "1", "2.5", "0"))
    assert no_server["orient"].absolute.reference_sigma_m == (1.0, 2.5, 0.0)
    with pytest.raises(Reached):  # the default: 5 m each
        orient_command.run(parse(orient_command, *PAIR))
    assert no_server["orient"].absolute.reference_sigma_m == (5.0, 5.0, 5.0)
    assert pair_command.run(parse(pair_command, *PAIR, "--reference-sigma", "3", "4", "6")) == 0
    params = no_server["pair"]
    assert params.orient.absolute.reference_sigma_m == (3.0, 4.0, 6.0)
    assert params.to_dict()["reference_sigma_m"] == [3.0, 4.0, 6.0]  # in the manifest
    # and the pair flow hands it to the orientation
    import prefect.artifacts

    import tasks.archive.pair

    monkeypatch.setattr(prefect.artifacts, "create_progress_artifact", lambda *a, **k: None)
    monkeypatch.setattr(tasks.archive.pair, "orientation_changes", lambda *a: None)
    with pytest.raises(Reached):
        no_server["real_pair_flow"].fn(params)
    assert no_server["orient"].absolute.reference_sigma_m == (3.0, 4.0, 6.0)


@pytest.mark.parametrize("values", [("-1", "5", "5"), ("5", "nan", "5"), ("5", "5", "inf")])
def test_bad_reference_sigma_is_refused_in_one_line(values, no_server, capsys):
    with pytest.raises(InputError, match="--reference-sigma takes three finite sigmas"):
        orient_command.run(parse(orient_command, *PAIR, "--reference-sigma", *values))
    assert "orient" not in no_server and "pair" not in no_server  # before anything ran
    for command in ("orient", "pair"):
        assert cli.main([command, *PAIR, "--reference-sigma", *values]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--reference-sigma" in err[0], err
    assert cli.main(["orient", *PAIR, "--reference-sigma", "1", "2"]) == 2  # two values
    assert "--reference-sigma" in capsys.readouterr().err


def correlated_gcps(truth, rng, error: CorrelatedGroundError, n: int = 150,
                    noise_px: float = 0.2) -> tuple[ControlPoint, ...]:
    """GCPs spread over the pair, measured with ``noise_px`` at their true image positions,
    their ground moved by a field correlated as ``error`` says (what a reference DEM's
    noise, canopy and tilt make of surface-matched GCPs)."""
    c, r = rng.uniform(50, 2950, n), rng.uniform(50, 2950, n)
    h = 400.0 + 1000.0 * rng.uniform(size=n)
    lon, lat = truth[0].localize(c, r, h)
    m_lon, m_lat = metres_per_degree(float(np.mean(lat)))
    x, y = (lon - lon.mean()) * m_lon, (lat - lat.mean()) * m_lat
    d = np.hypot(x[:, None] - x, y[:, None] - y)
    chol = np.linalg.cholesky(error.correlation(d) + 1e-9 * np.eye(n))
    e = chol @ rng.normal(size=(n, 3)) * np.sqrt(error.variance_m2)
    pts = {k: t.project(lon, lat, h) for k, t in zip(("left", "right"), truth, strict=True)}
    return tuple(ControlPoint(
        id=i, lon_deg=float(lon[i] + e[i, 0] / m_lon), lat_deg=float(lat[i] + e[i, 1] / m_lat),
        h_m=float(h[i] + e[i, 2]), sigma_xy_m=3.0, sigma_h_m=3.0,
        image_points={k: ImagePoint(float(p[0][i] + rng.normal(0, noise_px)),
                                    float(p[1][i] + rng.normal(0, noise_px)))
                      for k, p in pts.items()})
        for i in range(n))


def test_predicted_check_points_hold_under_correlated_gcp_errors(tmp_path):
    """150 GCPs whose ground errors are correlated (4 m east and north, 2 m up, over 4 km,
    on a 30 km pair of 10 m pixels), exact check points, no reference shift stated: pooled
    over 24 draws, the check points' RMS per image and axis is the predicted within 25 %
    (the draws' sampling error is about 10 %). The same errors taken as independent state
    under half of it (:mod:`tests.core.orientation.test_correlated_uncertainty`)."""
    delivered = models()
    truth = (delivered[0].with_params([1.2e-4, -0.8e-4, 0.5e-4, 1e-6, -2e-6, 0.0]),
             delivered[1].with_params([-0.9e-4, 1.5e-4, -0.7e-4, -2e-6, 1e-6, 0.0]))
    loaded = [LoadedModel(m, "pushbroom", tmp_path / f"{k}.json", None, (3000, 3000))
              for k, m in enumerate(delivered)]
    from core.orientation.absolute import AbsoluteConfig
    from core.orientation.adjust import AdjustConfig, ControlSet
    from core.orientation.frames import REFERENCE, FramePrior

    config = AbsoluteConfig(reference_sigma_m=(0.0, 0.0, 0.0))
    error = CorrelatedGroundError((16.0, 16.0, 4.0), 4000.0, 0)
    measured, predicted = [], []
    g = np.random.default_rng(5)
    c0, r0 = g.uniform(0, 2999, 300), g.uniform(0, 2999, 300)
    hh = 400.0 + 1000.0 * g.uniform(size=300)
    lo, la = truth[0].localize(c0, r0, hh)
    for seed in range(24):
        rng = np.random.default_rng(100 + seed)
        gcps = correlated_gcps(truth, rng, error)
        control = [ControlSet("surface", gcps, FramePrior(REFERENCE,
                                                          config.reference_sigma_m))]
        prod = orient_absolute.fn((("left", loaded[0]), ("right", loaded[1])), control,
                                  tmp_path, AdjustConfig(absolute=config))
        assert prod.predicted["reference_sigma_m"] == [0.0, 0.0, 0.0]
        for k, s in enumerate(check(prod.models, truth)):
            p = prod.adjustment.predict(k, lo, la, hh)
            measured.append((s.rms_col_px**2, s.rms_row_px**2))
            predicted.append((p.predicted_rms_col_px**2, p.predicted_rms_row_px**2))
    ratio = np.sqrt(np.mean(measured, axis=0) / np.mean(predicted, axis=0))
    assert ratio == pytest.approx([1.0, 1.0], abs=0.25), ratio

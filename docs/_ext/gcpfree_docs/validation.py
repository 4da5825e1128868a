"""The validation pages' tables and figures, drawn at build time from what the benches keep in
``bench/results/`` (nothing is rerun here): each table and figure is written into
``docs/validation/generated/`` as a Markdown snippet or a PNG that the hand-written pages
include, with the command that regenerates its numbers.

A results file that is missing makes its snippet say so (the page still builds); one that no
longer parses fails the build.
"""

from __future__ import annotations

import json
import re
import statistics
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[3]
RESULTS = ROOT / "bench" / "results"

# the command behind each results file (the benches' own docstrings say the same)
COMMANDS = {
    "relief_sweep.json": "python bench/validation/relief_sweep.py --out bench/results/relief_sweep.json",
    "relief_sweep_simple.json": (
        "python bench/validation/relief_sweep.py --errors simple "
        "--out bench/results/relief_sweep_simple.json"),
    "realistic_table.json": (
        "python bench/validation/realistic_table.py --out bench/results/realistic_table.json"),
    "realistic_table_spot_seeds.json": (
        "python bench/validation/realistic_table.py --cases spot:3:realistic spot:4:realistic "
        "spot:5:realistic --out bench/results/realistic_table_spot_seeds.json"),
    "realistic_table_hrs_seeds.json": (
        "python bench/validation/realistic_table.py --cases hrs:2:realistic hrs:3:realistic "
        "--out bench/results/realistic_table_hrs_seeds.json"),
    "independent_reference.json": (
        "python bench/validation/independent_reference.py "
        "--out bench/results/independent_reference.json"),
    "independent_reference_harsh.json": (
        "python bench/validation/independent_reference.py --canopy 0.7 --shift-m 15 "
        "--noise-m 6 --out bench/results/independent_reference_harsh.json"),
    "uncertainty_sweep.json": (
        "python bench/validation/uncertainty_sweep.py --out bench/results/uncertainty_sweep.json"),
    "prediction_check.json": (
        "python bench/validation/prediction_check.py --summary bench/results/prediction_check.json"),
    "dsm_wall.txt": "python bench/perf/bench_dsm_wall.py --repeat 3",
    "bench_pair_spot.txt": "python bench/perf/bench_pair.py --scene DIR",
    "bench_hrg_pool.txt": "python bench/perf/bench_hrg.py",
}


def _load(name: str) -> Any:
    path = RESULTS / name
    if not path.exists():
        return None
    return json.loads(path.read_text()) if name.endswith(".json") else path.read_text()


def source_line(*names: str) -> str:
    """Where the figures come from and the commands that make them again."""
    parts = [f"`bench/results/{n}` (`{COMMANDS[n]}`)" for n in names]
    return "Source: " + "; ".join(parts) + "."


def _missing(*names: str) -> list[str]:
    return [f"*Not available: `bench/results/{n}` is missing; `{COMMANDS[n]}` makes it.*"
            for n in names if not (RESULTS / n).exists()]


def _f(x: float | None, digits: int = 2) -> str:
    return "-" if x is None else f"{x:.{digits}f}"


def _table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> list[str]:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return out


# ---------------------------------------------------------------------------- accuracy


def relief_rows(sweep: list[dict[str, Any]]) -> list[list[str]]:
    rows = []
    for r in sorted(sweep, key=lambda r: r["factor"]):
        refused = r.get("refused")
        rows.append([f"{r['factor']:g}", _f(r["relief_m"], 1),
                     f"{r.get('qualified', '-')}/{r['windows']}" if not refused else
                     f"-/{r['windows']}",
                     str(r.get("gcps", 0)) if not refused else "0",
                     _f(r.get("check_rms_px")) if not refused else "refused"])
    return rows


def relief_snippet() -> list[str]:
    names = ("relief_sweep.json", "relief_sweep_simple.json")
    out = _missing(*names)
    header = ["relief scale", "median window relief (m)", "windows qualified", "GCPs",
              "check points, worst RMS (px)"]
    for name, title in zip(names, ("errors real products have (`--errors realistic`)",
                                   "the simulator's simple errors"), strict=True):
        data = _load(name)
        if data is None:
            continue
        out += [f"**{title}**", ""] + _table(header, relief_rows(data)) + [""]
    return out + [source_line(*names), ""]


def _pair(img: dict[str, Any], a: str, b: str) -> str:
    return f"{_f(img.get(a))} / {_f(img.get(b))}"


def realistic_rows(cases: list[dict[str, Any]]) -> list[list[str]]:
    rows = []
    for c in cases:
        left, right = c["images"]["left"], c["images"]["right"]
        rows.append([
            c["case"].replace("_", " "),
            " / ".join(f"{v:+.1f}" for v in c["reference_shift_m"]),
            f"{_pair(left, 'rms_col_px', 'rms_row_px')}, {_pair(right, 'rms_col_px', 'rms_row_px')}",
            (f"{_pair(left, 'beyond_col_px', 'beyond_row_px')}, "
            f"{_pair(right, 'beyond_col_px', 'beyond_row_px')}"),
            (f"{_pair(left, 'predicted_col_px', 'predicted_row_px')}, "
            f"{_pair(right, 'predicted_col_px', 'predicted_row_px')}")])
    return rows


def realistic_snippet() -> list[str]:
    names = ("realistic_table.json", "realistic_table_spot_seeds.json",
             "realistic_table_hrs_seeds.json")
    out = _missing(*names)
    cases = [c for n in names for c in (_load(n) or [])]
    header = ["scene", "reference shift E / N (m)", "check points P / L (px), left, right",
              "beyond the reference's shift", "predicted (with the reference's 5 m)"]
    out += _table(header, realistic_rows(cases)) + [""]
    return out + [source_line(*names), ""]


def independent_snippet() -> list[str]:
    names = ("independent_reference.json", "independent_reference_harsh.json")
    out = _missing(*names)
    for name in names:
        doc = _load(name)
        if doc is None:
            continue
        s = doc["settings"]
        out += [(f"**Canopy share {s['canopy']:g}, misregistration {s['shift_m']:g} m, noise "
                f"{s['noise_m']:g} m over {s['corr_m']:g} m**"), ""]
        rows = []
        for scene in doc["scenes"]:
            cells = [scene["scene"].replace("_", " ")]
            for key in ("simulator", "independent"):
                run = scene.get(key)
                if run is None:
                    cells.append("-")
                    continue
                left, right = run["images"]["left"], run["images"]["right"]
                cells.append(f"{_pair(left, 'beyond_col_px', 'beyond_row_px')}, "
                             f"{_pair(right, 'beyond_col_px', 'beyond_row_px')}")
            rows.append(cells)
        out += _table(["scene", "simulator's reference", "independent reference"], rows) + [""]
    return out + [
        "Check points beyond the reference's own shift, P / L RMS in px, left then right.", "",
        source_line(*names), ""]


def _ratios(scenes: list[dict[str, Any]]) -> list[tuple[str, str, float, float]]:
    """(scene, axis, predicted, measured) beyond the GCPs' common error, per image axis."""
    out = []
    for s in scenes:
        for img in s["images"].values():
            for axis, k in (("columns", 0), ("rows", 1)):
                out.append((s["scene"], axis, img["predicted_beyond_common_px"][k],
                            img["measured_beyond_common_px"][k]))
    return out


def _group(scene: str) -> str:
    return scene.split("_")[0]


def prediction_snippet() -> list[str]:
    name = "prediction_check.json"
    doc = _load(name)
    if doc is None:
        return _missing(name)
    ratios = _ratios(doc["scenes"])
    rows = []
    for group in ("spot", "hrs", "tiny"):
        rs = [m / p for s, _, p, m in ratios if _group(s) == group]
        within = sum(0.7 <= r <= 1.5 for r in rs)
        rows.append([group, str(len(rs)), f"{within}", _f(statistics.median(rs))])
    total = [m / p for _, _, p, m in ratios]
    rows.append(["all", str(len(total)), f"{sum(0.7 <= r <= 1.5 for r in total)}",
                 _f(statistics.median(total))])
    return [(f"{doc['within_0.7_1.5']} of the {doc['n_ratios']} ratios measured / predicted lie "
            "within 0.7-1.5 (check points beyond the GCPs' common error, per image and axis)."),
            ""] + _table(["scenes", "ratios", "within 0.7-1.5", "median ratio"], rows) + [
        "", source_line(name), ""]


def sweep_snippet() -> list[str]:
    name = "uncertainty_sweep.json"
    data = _load(name)
    if data is None:
        return _missing(name)
    rows = []
    for s in data:
        left, right = s["images"]["left"], s["images"]["right"]
        rows.append([f"tiny {s['seed']}", " ".join(f"{v:.2f}" for v in s["centre"]),
                     " / ".join(f"{v:+.1f}" for v in s["reference_shift_m"]),
                     (f"{_pair(left, 'rms_col_px', 'rms_row_px')}, "
                     f"{_pair(right, 'rms_col_px', 'rms_row_px')}"),
                     (f"{_pair(left, 'predicted_rms_col_px', 'predicted_rms_row_px')}, "
                     f"{_pair(right, 'predicted_rms_col_px', 'predicted_rms_row_px')}")])
    return _table(["scene", "centre (lon lat)", "reference shift E / N (m)",
                   "check points P / L (px), left, right", "predicted"], rows) + [
        "", source_line(name), ""]


# ---------------------------------------------------------------------------- speed


def dsm_wall(text: str) -> dict[str, float]:
    """The medians of ``bench_dsm_wall.py``: CARS's time and gcpfree's first and later runs."""
    out = {"cars_s": float(re.search(r"CARS ([\d.]+) s", text).group(1))}
    for kind in ("first", "later"):
        m = re.search(rf"^\s+gcpfree\s+{kind} run:\s+([\d.]+) s", text, re.MULTILINE)
        out[f"gcpfree_{kind}_s"] = float(m.group(1))
    return out


def pair_rounds(text: str) -> list[dict[str, float]]:
    """Each round of ``bench_pair.py``: wall time and peak memory with 1 and 2 workers."""
    runs = re.findall(r"^pair on \S+, (\d) worker\(s\): ([\d.]+) s, peak RSS (\d+) MB", text,
                      re.MULTILINE)
    rounds = []
    for i in range(0, len(runs) - 1, 2):
        (w1, t1, m1), (w2, t2, m2) = runs[i], runs[i + 1]
        if (w1, w2) == ("1", "2"):
            rounds.append({"one_s": float(t1), "two_s": float(t2), "one_mb": float(m1),
                           "two_mb": float(m2)})
    return rounds


# stated in the README when measured, not kept in bench/results by their benches yet
STATED = [
    ("RPC projection of 1 M points", "gcpfree 8 ms, 16.9x faster than rpcm (load 3.5)",
     "python bench/perf/bench_rpc.py"),
    ("ortho of a 4000x4000 spot crop", "gcpfree 2.7 s, GDAL's RPC warp 7.1 s (2.67x)",
     "python bench/perf/bench_ortho.py --scene SCENE_DIR --crop 4000"),
    ("ortho of a whole spot scene (7574x7474)", "gcpfree 7.0 s, GDAL 23.1 s (3.30x)",
     "python bench/perf/bench_ortho.py --scene SCENE_DIR"),
    ("DEM coregistration (Nuth & Kaab), SRTM tile", ("fit time 0.49x xdem 0.2.3's; shift error "
     "0.0004 px against xdem's 0.0035 px"), "python bench/perf/bench_coregister.py"),
]

# the same, as gcpfree's time over the peer's (what, peer, ratio)
STATED_RATIOS = [("ortho, 4000x4000 crop", "GDAL", 2.7 / 7.1),
                 ("ortho, whole spot scene", "GDAL", 7.0 / 23.1),
                 ("coregistration fit, SRTM tile", "xdem", 0.49),
                 ("RPC projection, 1 M points", "rpcm", 1 / 16.9)]


def speed_snippet() -> list[str]:
    out = _missing("dsm_wall.txt", "bench_pair_spot.txt")
    rows = []
    wall = _load("dsm_wall.txt")
    if wall is not None:
        w = dsm_wall(wall)
        rows.append(["`gcpfree dsm`, Pleiades Reunion ROI, a later run",
                     (f"{w['gcpfree_later_s']:.1f} s against CARS {w['cars_s']:.0f} s "
                     f"({w['gcpfree_later_s'] / w['cars_s']:.3f}x)"),
                     f"`{COMMANDS['dsm_wall.txt']}`"])
        rows.append(["`gcpfree dsm`, the same, a user's first run",
                     (f"{w['gcpfree_first_s']:.1f} s ({w['gcpfree_first_s'] / w['cars_s']:.3f}x "
                     "CARS)"), f"`{COMMANDS['dsm_wall.txt']}`"])
    pair = _load("bench_pair_spot.txt")
    if pair is not None:
        last = pair_rounds(pair)[-1]
        rows.append(["`gcpfree pair`, simulated spot pair (36 Mpx, realistic errors, lens)",
                     (f"{last['two_s']:.0f} s with 2 workers ({last['two_mb'] / 1024:.1f} GB), "
                     f"{last['one_s']:.0f} s with 1 ({last['one_s'] / last['two_s']:.2f}x)"),
                     f"`{COMMANDS['bench_pair_spot.txt']}`"])
    rows += [[what, f"{figure} (*)", f"`{cmd}`"] for what, figure, cmd in STATED]
    return out + _table(["what", "figure (2 cores)", "command"], rows) + [
        "", "(*) as stated when measured during 0.1.0: that bench keeps no results file yet.", ""]


# ---------------------------------------------------------------------------- figures


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _finish(plt: Any, fig: Any, ax: Any, path: Path, labels: tuple[str, str, str],
            legend: dict[str, Any] | None = None) -> bool:
    """Axis labels and title, a legend with ``legend``'s options (none when None), a light
    grid; the figure written to ``path`` and closed."""
    xlabel, ylabel, title = labels
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    if legend is not None:
        ax.legend(**legend)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return True


def relief_figure(path: Path) -> bool:
    sweeps = {n: _load(n) for n in ("relief_sweep.json", "relief_sweep_simple.json")}
    if not any(sweeps.values()):
        return False
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4), dpi=110)
    for (name, data), label, mark in zip(sweeps.items(), ("realistic errors", "simple errors"),
                                         ("o-", "s--"), strict=True):
        if not data:
            continue
        ok = [r for r in sorted(data, key=lambda r: r["relief_m"]) if not r.get("refused")]
        ax.plot([r["relief_m"] for r in ok], [r["check_rms_px"] for r in ok], mark, label=label)
        for r in data:
            if r.get("refused"):
                ax.plot(r["relief_m"], 0.0, "kx", ms=9)
                ax.annotate("refused", (r["relief_m"], 0.0), textcoords="offset points",
                            xytext=(4, 6), fontsize=8)
    ax.axhline(0.5, color="0.6", lw=0.8, ls=":")
    ax.set_xscale("log")
    return _finish(plt, fig, ax, path, ("median window relief (m)", "check points, worst RMS (px)",
                   "GCP-free orientation against relief (simulated tiny pair, 40 m pixels)"), {})


def prediction_figure(path: Path) -> bool:
    doc = _load("prediction_check.json")
    if doc is None:
        return False
    plt = _pyplot()
    ratios = _ratios(doc["scenes"])
    fig, ax = plt.subplots(figsize=(6, 5.2), dpi=110)
    colours = {"spot": "tab:blue", "hrs": "tab:orange", "tiny": "tab:green"}
    for group, colour in colours.items():
        for axis, mark in (("columns", "o"), ("rows", "^")):
            pts = [(p, m) for s, a, p, m in ratios if _group(s) == group and a == axis]
            ax.scatter([p for p, _ in pts], [m for _, m in pts], c=colour, marker=mark, s=22,
                       label=f"{group}, {axis}", alpha=0.8)
    top = max(max(p, m) for _, _, p, m in ratios) * 1.1
    xs = [0, top]
    ax.plot(xs, xs, "k-", lw=0.8, label="measured = predicted")
    ax.fill_between(xs, [0.7 * x for x in xs], [1.5 * x for x in xs], color="0.85",
                    label="0.7-1.5", zorder=0)
    ax.set_xlim(0, top)
    ax.set_ylim(0, top)
    return _finish(plt, fig, ax, path, (
        "predicted check-point RMS beyond the GCPs' common error (px)",
        "measured, beyond the GCPs' common error (px)",
        "Stated against measured accuracy, 19 simulated scenes"), {"fontsize": 7, "ncol": 2})


def speed_figure(path: Path) -> bool:
    wall, pair = _load("dsm_wall.txt"), _load("bench_pair_spot.txt")
    if wall is None and pair is None:
        return False
    plt = _pyplot()
    bars: list[tuple[str, float, str]] = []
    if wall is not None:
        w = dsm_wall(wall)
        bars += [("CARS 1.3, DSM of the Reunion ROI", w["cars_s"], "0.55"),
                 ("gcpfree dsm, first run", w["gcpfree_first_s"], "tab:blue"),
                 ("gcpfree dsm, later run", w["gcpfree_later_s"], "tab:blue")]
    if pair is not None:
        last = pair_rounds(pair)[-1]
        bars += [("gcpfree pair, spot, 1 worker", last["one_s"], "tab:green"),
                 ("gcpfree pair, spot, 2 workers", last["two_s"], "tab:green")]
    fig, ax = plt.subplots(figsize=(7, 3.2), dpi=110)
    labels = [b[0] for b in bars][::-1]
    ax.barh(labels, [b[1] for b in bars][::-1], color=[b[2] for b in bars][::-1])
    for i, (_, seconds, _) in enumerate(bars[::-1]):
        ax.annotate(f"{seconds:.1f} s", (seconds, i), xytext=(3, -3),
                    textcoords="offset points", fontsize=8)
    return _finish(plt, fig, ax, path, ("wall time on 2 cores (s)", "",
                                         "Speed, from the shell as a user waits"))


def peers_figure(path: Path) -> bool:
    """gcpfree's time as a share of each peer's: CARS from ``bench/results/``, the others as
    stated (hatched)."""
    plt = _pyplot()
    bars: list[tuple[str, float, bool]] = []
    wall = _load("dsm_wall.txt")
    if wall is not None:
        w = dsm_wall(wall)
        bars.append(("DSM, Reunion ROI (CARS)", w["gcpfree_later_s"] / w["cars_s"], False))
    bars += [(f"{what} ({peer})", ratio, True) for what, peer, ratio in STATED_RATIOS]
    fig, ax = plt.subplots(figsize=(7, 3.0), dpi=110)
    rows = bars[::-1]
    for i, (_, ratio, stated) in enumerate(rows):
        ax.barh(i, ratio, color="tab:blue", alpha=0.55 if stated else 0.9,
                hatch="//" if stated else None, edgecolor="tab:blue")
        ax.annotate(f"{ratio:.2f}x", (ratio, i), xytext=(3, -3), textcoords="offset points",
                    fontsize=8)
    ax.set_yticks(range(len(rows)), [r[0] for r in rows])
    ax.axvline(1.0, color="0.4", lw=0.8, ls=":")
    ax.set_xlim(0, 1.1)
    return _finish(plt, fig, ax, path, (
        "gcpfree's time over the peer's (hatched: as stated, no results file)", "",
        "Speed against the peers, 2 cores"))


SNIPPETS: dict[str, Callable[[], list[str]]] = {
    "relief.md": relief_snippet, "realistic.md": realistic_snippet,
    "independent.md": independent_snippet, "prediction.md": prediction_snippet,
    "sweep.md": sweep_snippet, "speed.md": speed_snippet,
}
FIGURES: dict[str, Callable[[Path], bool]] = {
    "relief_sweep.png": relief_figure, "predicted_vs_measured.png": prediction_figure,
    "speed.png": speed_figure, "peers.png": peers_figure,
}


def write_all(out: Path) -> list[str]:
    """Every snippet and figure into ``out``; the names written (a figure whose results are
    missing is not drawn, and its page says so through the snippet)."""
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, make in SNIPPETS.items():
        text = "\n".join(make()) + "\n"
        path = out / name
        if not path.exists() or path.read_text() != text:
            path.write_text(text)
        written.append(name)
    for name, draw in FIGURES.items():
        if draw(out / name):
            written.append(name)
    return written

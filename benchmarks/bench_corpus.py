"""Layouts judged on designs nobody tuned for: the corpus of `benchmarks/designs.py`.

Run from the repository root::

    python benchmarks/bench_corpus.py                          # every design, net and size
    python benchmarks/bench_corpus.py --designs bumps l-facade --nets snet
    python benchmarks/bench_corpus.py --summarize A.json B.json  # compare two runs

Every design is laid out (`fabplan.layout_surface`) and solved gliding on it
(`fabplan.glide`) with each net type (snet, orthogonal, isogonal 60 deg, const-radius) at
two panel sizes (about 150 and 500 panels). Each case records how it ended (converged,
the solver's status, or the one-line refusal), the share of the design covered, how far
the net's lines turn within the surface (measured here, independently of fabplan: the
angle between consecutive edges of a line projected onto the tangent plane of the star),
the angle range, folds, the boundary panels that cross themselves or overlap (counted on
the surface, `fabplan.layout.trim.Soundness`; the total is printed last) and seconds.
A run writes ``benchmarks/results/corpus-<label>.json``
and prints a markdown table; ``--summarize`` prints the median and worst line turn and the
coverage per net type for several runs side by side (for example the code of two commits,
each run with its checkout on ``PYTHONPATH``).

``--hard`` runs the hard starts instead (`designs.HARD_STARTS`: seeded noisy domes,
saddles, towers, helicoids, facades and the bundled nets), each optimized as it is
(`fabplan.optimize`) as ``snet``, ``isogonal`` at 60 deg and ``const-radius``. Each case
records fabplan's status and exit code (0 converged, 3 not, 2 refused) beside an
independent check of the net written (`check_buildable.py`, no fabplan code: darts, lines
turning over 90 deg, edge ratios); the summary counts per net type the cases converged,
converged and buildable by that check, converged but crumpled (which must be none), and
every other status::

    python benchmarks/bench_corpus.py --hard --label hard-baseline
    python benchmarks/bench_corpus.py --hard --starts-named dome-08 tower-14 --nets snet
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from check_buildable import check  # noqa: E402
from designs import DESIGNS, HARD_STARTS  # noqa: E402

import fabplan  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
NETS = [("snet", None), ("orthogonal", None), ("isogonal", 60.0), ("const-radius", None)]
PANELS = (150, 500)
HARD_NETS = [("snet", None), ("isogonal", 60.0), ("const-radius", None)]


def line_turns_deg(X: np.ndarray, stars: np.ndarray) -> np.ndarray:
    """Turn of both lines at every star, projected on the star's tangent plane (degrees)."""
    if len(stars) == 0:
        return np.zeros(0)
    P = X[stars]
    v = P[:, 0]
    n = np.cross(P[:, 3] - P[:, 1], P[:, 4] - P[:, 2])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    out = []
    for a, b in ((1, 3), (2, 4)):
        d0, d1 = v - P[:, a], P[:, b] - v
        d0 = d0 - np.sum(d0 * n, axis=1, keepdims=True) * n
        d1 = d1 - np.sum(d1 * n, axis=1, keepdims=True) * n
        c = np.sum(d0 * d1, axis=1) / np.linalg.norm(d0, axis=1) / np.linalg.norm(d1, axis=1)
        out.append(np.degrees(np.arccos(np.clip(c, -1, 1))))
    return np.concatenate(out)


def run_case(design, net: str, angle: float | None, panels: int, starts: int = 1) -> dict:
    h = math.sqrt(design.area / panels)
    record: dict = {"design": design.name, "net": net if angle is None else f"{net}-{angle:g}",
                    "panel_size": round(h, 4)}
    t0 = time.perf_counter()
    try:
        if starts > 1:      # several starts, the fairest kept (`fabplan.layout.starts`)
            from fabplan.layout.starts import glide_fairest

            _, result = glide_fairest(design, h, net, angle=angle or 90.0, net_angle=angle,
                                      starts=starts)
            record["starts"] = result.properties["layout_starts"]
        else:
            layout = fabplan.layout_surface(design, h, angle=angle or 90.0)
            result = fabplan.glide(layout, net, angle=angle)
    except fabplan.FabplanError as exc:
        record.update(status="refused", message=str(exc), seconds=time.perf_counter() - t0)
        return record
    X = result.mesh.vertices
    stars = result.mesh.stars
    turns = line_turns_deg(X, stars)
    props = result.properties
    angle_stats = props.get("intersection_angle_deg") or {}
    folds = props.get("folds") or {}
    record.update(
        status=result.status, converged=bool(result.converged),
        message=getattr(result, "message", ""),
        coverage=props.get("coverage"),
        coverage_net=props.get("coverage_net"),
        boundary_panels=(props.get("boundary_panels") or {}).get("count"),
        boundary_flipped=len((props.get("boundary_panels") or {}).get("flipped") or []),
        boundary_patches=len((props.get("boundary_panels") or {}).get("patches") or []),
        # boundary panels crossing themselves, overlapping one another or the net, or
        # sharing a side the same way: measured on the surface (0 in a sound cladding)
        boundary_crossings=_crossings(props.get("boundary_panels") or {}),
        off_design_area=((props.get("boundary_panels") or {}).get("off_design") or {}).get("area"),
        line_turn_max=float(turns.max()) if turns.size else None,
        line_turn_median=float(np.median(turns)) if turns.size else None,
        line_turn_p95=float(np.percentile(turns, 95)) if turns.size else None,
        angle_min=angle_stats.get("min"), angle_max=angle_stats.get("max"),
        folded=folds.get("folded"),
        quads=int(np.sum(result.mesh.face_sizes == 4)),
        seconds=time.perf_counter() - t0)
    return record


def run_hard_case(name: str, net: str, angle: float | None) -> dict:
    """Optimize the hard start `name` as `net`; fabplan's status beside the independent
    check of the net it writes."""
    start = HARD_STARTS[name]()
    record: dict = {"start": name, "net": net if angle is None else f"{net}-{angle:g}",
                    "vertices": start.vertex_count, "start_check": check(start.vertices, start.faces)}
    t0 = time.perf_counter()
    try:
        result = fabplan.optimize(start, net, angle=angle)
    except fabplan.FabplanError as exc:
        record.update(status="refused", exit=2, converged=False, message=str(exc),
                      seconds=time.perf_counter() - t0)
        return record
    seconds = time.perf_counter() - t0
    own = check(result.mesh.vertices, result.mesh.faces)
    folds = result.properties.get("folds") or {}
    record.update(status=result.status, exit=0 if result.converged else 3,
                  converged=bool(result.converged), message=result.message,
                  iterations=result.iterations, check=own, folded=folds.get("folded"),
                  crumpled=bool(result.converged and not own["buildable"]),
                  seconds=seconds)
    return record


def hard_summary(records: list) -> str:
    """Counts per net type: converged, converged and buildable (independent check),
    converged but crumpled, and the other statuses."""
    rows = ["| net | cases | converged | converged and buildable | converged but crumpled | "
            "other statuses (exit 3 or 2) |", "|---|---|---|---|---|---|"]
    groups = sorted({r["net"] for r in records}) + ["all"]
    for net in groups:
        cases = [r for r in records if net in ("all", r["net"])]
        ok = [r for r in cases if r["converged"]]
        good = [r for r in ok if r["check"]["buildable"]]
        others: dict = {}
        for r in cases:
            if not r["converged"]:
                others[r["status"]] = others.get(r["status"], 0) + 1
        rows.append(f"| {net} | {len(cases)} | {len(ok)} | {len(good)} | {len(ok) - len(good)} | "
                    + ", ".join(f"{k} {v}" for k, v in sorted(others.items())) + " |")
    return "\n".join(rows)


def write_run(label: str, records: list, **extra) -> Path:
    """Write a run's records to ``results/corpus-<label>.json`` with where it ran."""
    RESULTS.mkdir(exist_ok=True)
    out = RESULTS / f"corpus-{label}.json"
    out.write_text(json.dumps({"label": label, "fabplan": fabplan.__file__,
                               "machine": f"{platform.machine()}, {platform.python_version()}",
                               **extra, "cases": records}, indent=1))
    return out


def run_hard(args) -> int:
    records = []
    names = args.starts_named or list(HARD_STARTS)
    for name in names:
        for net, angle in HARD_NETS:
            if net not in args.nets:
                continue
            r = run_hard_case(name, net, angle)
            records.append(r)
            own = r.get("check") or {}
            print(f"{r['start']:<12} {r['net']:<13} {r['status']:<12} exit {r['exit']} "
                  f"darts {own.get('darts', '-')} turn {_fmt(own.get('turn_max'))} "
                  f"ratio {_fmt(own.get('edge_ratio_max'), '.2f')} {r['seconds']:.1f} s", flush=True)
    out = write_run(args.label, records, summary=hard_summary(records))
    print(hard_summary(records))
    print(f"wrote {out}")
    return 0


def _crossings(record: dict) -> int | None:
    """Panels crossing themselves plus pairs of pieces overlapping or clashing at a side,
    from a net's ``boundary_panels`` record (None where it does not say)."""
    crossings = record.get("crossings")
    if crossings is None:
        return None
    return int(crossings["self_crossing"] + crossings["overlapping"] + crossings["edge_clashes"])


def _fmt(v, spec=".1f") -> str:
    return "-" if v is None else format(v, spec)


def table(records: list) -> str:
    rows = ["| design | net | panel | status | coverage % (full panels) | boundary panels | "
            "line turn max / median deg | angles deg | s |", "|---|---|---|---|---|---|---|---|---|"]
    for r in records:
        cov = None if r.get("coverage") is None else 100 * r["coverage"]
        net = None if r.get("coverage_net") is None else 100 * r["coverage_net"]
        status = r["status"] + (" (folded)" if r.get("folded") else "")
        if r["status"] == "refused":
            status = "refused: " + r["message"].split(": ", 1)[-1][:60]
        rows.append(f"| {r['design']} | {r['net']} | {r['panel_size']:.2f} | {status} | "
                    f"{_fmt(cov, '.2f')} ({_fmt(net)}) | {_fmt(r.get('boundary_panels'), 'd')} | "
                    f"{_fmt(r.get('line_turn_max'))} / {_fmt(r.get('line_turn_median'))} | "
                    f"{_fmt(r.get('angle_min'))} .. {_fmt(r.get('angle_max'))} | {r['seconds']:.1f} |")
    return "\n".join(rows)


def summarize(paths: list[Path]) -> str:
    runs = [json.loads(p.read_text()) for p in paths]
    head = "| net | " + " | ".join(
        f"{r['label']}: converged, coverage median / min %, line turn at the 95th "
        "percentile median / worst, line turn median / worst of the cases' sharpest, deg"
        for r in runs) + " |"
    rows = [head, "|---|" + "---|" * len(runs)]
    for net in sorted({c["net"] for r in runs for c in r["cases"]}):
        cells = []
        for r in runs:
            cases = [c for c in r["cases"] if c["net"] == net]
            done = [c for c in cases if c.get("line_turn_max") is not None]
            cov = [100 * c["coverage"] for c in done if c.get("coverage") is not None]
            turn = [c["line_turn_max"] for c in done]
            p95 = [c["line_turn_p95"] for c in done if c.get("line_turn_p95") is not None]
            ok = sum(1 for c in cases if c.get("converged"))
            cells.append(f"{ok} of {len(cases)}, {_fmt(np.median(cov) if cov else None)} / "
                         f"{_fmt(min(cov) if cov else None)}, "
                         f"{_fmt(np.median(p95) if p95 else None)} / "
                         f"{_fmt(max(p95) if p95 else None)}, "
                         f"{_fmt(np.median(turn) if turn else None)} / "
                         f"{_fmt(max(turn) if turn else None)}")
        rows.append(f"| {net} | " + " | ".join(cells) + " |")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--designs", nargs="*", default=list(DESIGNS), choices=list(DESIGNS))
    parser.add_argument("--nets", nargs="*", default=[n for n, _ in NETS])
    parser.add_argument("--label", default=datetime.date.today().isoformat())
    parser.add_argument("--summarize", nargs="*", type=Path)
    parser.add_argument("--starts", type=int, default=1,
                        help="lay out and solve every case from this many starts and keep the "
                             "fairest (fabplan.layout.starts; 1: one layout, one solve)")
    parser.add_argument("--hard", action="store_true",
                        help="optimize the hard starts (designs.HARD_STARTS) instead of laying "
                             "out the designs")
    parser.add_argument("--starts-named", nargs="*", default=None, choices=list(HARD_STARTS),
                        metavar="START", help="with --hard: these starts only")
    args = parser.parse_args(argv)
    if args.hard:
        if args.nets == [n for n, _ in NETS]:
            args.nets = [n for n, _ in HARD_NETS]
        return run_hard(args)
    if args.summarize:
        print(summarize(args.summarize))
        return 0
    records = []
    for name in args.designs:
        design = DESIGNS[name]()
        for net, angle in NETS:
            if net not in args.nets:
                continue
            for panels in PANELS:
                records.append(run_case(design, net, angle, panels, args.starts))
                r = records[-1]
                print(f"{r['design']:<14} {r['net']:<13} {r['panel_size']:6.2f} {r['status']:<14} "
                      f"coverage {_fmt(None if r.get('coverage') is None else 100 * r['coverage'], '.2f')} "
                      f"boundary {r.get('boundary_panels')} flipped {r.get('boundary_flipped')} "
                      f"patches {r.get('boundary_patches')} "
                      f"crossings {r.get('boundary_crossings')} "
                      f"off design {_fmt(r.get('off_design_area'), '.3g')} "
                      f"turn {_fmt(r.get('line_turn_max'))} {r['seconds']:.1f} s", flush=True)
    out = write_run(args.label, records)
    print(table(records))
    crossings = [r["boundary_crossings"] for r in records if r.get("boundary_crossings") is not None]
    print(f"boundary panels crossing or overlapping: {sum(crossings)} in {len(crossings)} layouts")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

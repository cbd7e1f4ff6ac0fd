"""Parallel studies: candidates per minute on 1, 2 and N Dask workers, against the serial
run, and what scheduling costs per candidate.

Run from the repository root::

    python benchmarks/bench_parallel.py              # the 24-candidate stadium sweep and the short sweep
    python benchmarks/bench_parallel.py --quick      # the short sweep only
    python benchmarks/bench_parallel.py --workers 1 2 4

Cases:

- ``stadium-sweep``: the stadium template (`fabplan templates stadium`) as a sweep of 24
  candidates: the baseline, linear Weingarten at 38, 44 and 50 deg and isogonal at 60 and
  70 deg, each at panel sizes 3.0 and 3.5 m and mold tolerances 1 and 2 mm (12 solves:
  the tolerances share them).
- ``saddle-sweep``: short candidates (about a second each): a 4 x 4 m saddle, the
  baseline, minimal and CMC at panel sizes 0.6, 0.7 and 0.8 m and mold tolerances 1.5 and
  3 mm (18 candidates, 9 solves). Here scheduling is a visible share of the time.

Every case runs the serial study (`fabplan.study.run_study`, in this process), then the
parallel one (`run_study_parallel`) on a fresh `LocalCluster` of each worker count, and
writes the files of each run (`write_study`: with workers, they make the candidates'
files, as the command does). The
cluster's start is timed apart: a user pays it once per command. A parallel run makes the
candidates' files on the workers during the run (`files=True`, as the command does), so
compare whole studies (`total_s`: run and writing); scheduling overhead per candidate is
(1-worker total - serial total) / candidates. The runs' study records are
compared apart from timings: they must be identical.

Results are printed as a markdown table and written as JSON to
``benchmarks/results/parallel-<date>.json``. The machine is shared: check ``uptime``.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fabplan.study.parallel import run_study_parallel  # noqa: E402
from fabplan.study.report import study_record, write_study  # noqa: E402
from fabplan.study.run import run_study  # noqa: E402
from fabplan.study.spec import read_study  # noqa: E402
from fabplan.study.templates import copy_template  # noqa: E402

STADIUM_SWEEP = """
[panels]
size = [3.0, 3.5]

[limits]
max_deviation_mm = 150
mold_tolerance_mm = [1.0, 2.0]
max_molds = 100
max_kink_deg = 10

[cost]
mold = 100
double_curved_panel = 4

[[candidates]]
net = "linear-weingarten"
angle = [38, 44, 50]

[[candidates]]
net = "isogonal"
angle = [60, 70]
"""

SADDLE_SWEEP = """
[study]
name = "Short candidates"

[design]
surface = "hyperbolic-paraboloid"
parameters = { width = 4, depth = 4, rise = 1.2 }
triangles = 3000

[panels]
size = [0.6, 0.7, 0.8]

[limits]
max_deviation_mm = 200
mold_tolerance_mm = [1.5, 3]

[[candidates]]
net = "minimal"

[[candidates]]
net = "cmc"
"""


def stadium_sweep(folder: Path) -> Path:
    """The stadium template with its panels, limits and candidates made a sweep."""
    copy_template("stadium", folder / "stadium-sweep.toml")
    path = folder / "stadium-sweep.toml"
    text = path.read_text(encoding="utf-8")
    head = text[:text.index("[panels]")]
    path.write_text(head + STADIUM_SWEEP, encoding="utf-8")
    return path


def saddle_sweep(folder: Path) -> Path:
    path = folder / "saddle-sweep.toml"
    path.write_text(SADDLE_SWEEP, encoding="utf-8")
    return path


def _without_timings(value):
    if isinstance(value, dict):
        return {k: _without_timings(v) for k, v in value.items() if "second" not in k}
    if isinstance(value, list):
        return [_without_timings(v) for v in value]
    return value


def run_case(name: str, path: Path, worker_counts: list[int], folder: Path) -> list[dict]:
    from distributed import Client, LocalCluster

    study = read_study(path)
    count = len(study.candidates)
    solves = len({c.solve_key for c in study.candidates})
    rows, reference = [], None
    for workers in [0, *worker_counts]:
        cluster_seconds = 0.0
        clock = time.perf_counter()
        if workers == 0:
            result = run_study(study)
        else:
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   dashboard_address=None)
            client = Client(cluster)
            cluster_seconds = time.perf_counter() - clock
            clock = time.perf_counter()
            result = run_study_parallel(study, client=client, files=True)
        run_seconds = time.perf_counter() - clock
        clock = time.perf_counter()
        write_study(result, folder / f"{name}-{workers}", client=client if workers else None)
        write_seconds = time.perf_counter() - clock
        if workers:
            client.close()
            cluster.close()
        record = _without_timings(study_record(result))
        same = reference is None or record == reference
        reference = reference or record
        rows.append({
            "case": name, "workers": workers or "serial", "candidates": count, "solves": solves,
            "failed": sum(c.failed for c in result.candidates),
            "cluster_start_s": round(cluster_seconds, 2), "run_s": round(run_seconds, 2),
            "write_s": round(write_seconds, 2),
            "candidates_per_min": round(60 * count / run_seconds, 2),
            "total_s": round(run_seconds + write_seconds, 2),
            "same_study_json": same,
        })
        print(f"  {name}: {rows[-1]['workers']} -> run {run_seconds:.1f} s, write "
              f"{write_seconds:.1f} s", flush=True)
    serial = rows[0]["run_s"]
    one = next((r for r in rows if r["workers"] == 1), None)
    for r in rows:
        r["speedup_vs_serial"] = round(serial / r["run_s"], 2)
        if one is not None:
            r["speedup_vs_1_worker"] = round(one["run_s"] / r["run_s"], 2)
            r["total_speedup_vs_1_worker"] = round(one["total_s"] / r["total_s"], 2)
    if one is not None:
        # whole studies: a parallel run makes the candidates' files during the run
        rows[0]["overhead_per_candidate_s"] = round((one["total_s"] - rows[0]["total_s"]) / count, 3)
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="the short sweep only")
    parser.add_argument("--workers", type=int, nargs="+", default=None,
                        help="worker counts (default: 1, 2 and the cores if more)")
    parser.add_argument("--output", type=Path, default=None)
    args = parser.parse_args(argv)
    cores = os.cpu_count() or 1
    counts = args.workers or sorted({1, 2, cores})
    rows: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        cases = [("saddle-sweep", saddle_sweep(folder))]
        if not args.quick:
            cases.insert(0, ("stadium-sweep", stadium_sweep(folder)))
        for name, path in cases:
            rows += run_case(name, path, counts, folder)
    columns = ["case", "workers", "candidates", "solves", "run_s", "write_s", "total_s",
               "candidates_per_min", "speedup_vs_serial", "speedup_vs_1_worker",
               "total_speedup_vs_1_worker", "cluster_start_s", "same_study_json"]
    print("\n| " + " | ".join(columns) + " |\n|" + "---|" * len(columns))
    for r in rows:
        print("| " + " | ".join(str(r.get(c, "")) for c in columns) + " |")
    for r in rows:
        if "overhead_per_candidate_s" in r:
            print(f"{r['case']}: scheduling overhead {r['overhead_per_candidate_s']:.3f} s per "
                  "candidate (1 worker against the serial run)")
    output = args.output or ROOT / "benchmarks" / "results" / \
        f"parallel-{datetime.date.today().isoformat()}.json"
    output.write_text(json.dumps({"machine": {"cores": cores, "load": os.getloadavg()},
                                  "rows": rows}, indent=1) + "\n", encoding="utf-8")
    print(f"wrote {output}")
    return 0 if all(r["same_study_json"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())

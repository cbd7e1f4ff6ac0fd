"""A template study side by side with an earlier commit: wall time, CPU time and peak memory
of the whole command, runs alternating, and whether both recommend the same.

Run from the repository root::

    python benchmarks/bench_study.py --against bc82b5f                 # stadium, 3 rounds
    python benchmarks/bench_study.py --against bc82b5f --template tower --rounds 2

Each run is ``fabplan study TEMPLATE -o DIR -q`` in a fresh process started from a
neutral folder (``python -c`` puts the current folder first on ``sys.path``), timed with
``/usr/bin/time`` semantics from `resource.getrusage` of the child; the earlier commit
runs from a detached worktree made here (its compiled kernels built in place when it has
any) and removed at the end. The rounds alternate the two codes, so load on the machine
falls on both alike; read the medians, and check ``uptime`` (printed before and after).

Results are printed as a markdown table and written as JSON to
``benchmarks/results/study-<template>-<date>.json``.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = Path(__file__).resolve().parent / "results"
RUN = "import sys; from fabplan.cli import main; sys.exit(main())"


def checkout(commit: str, folder: Path) -> Path:
    """A detached worktree of `commit` in `folder`, its C extensions built in place."""
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(folder), commit],
                   check=True, capture_output=True)
    if (folder / "setup.py").exists():
        subprocess.run([sys.executable, "setup.py", "-q", "build_ext", "--inplace"], cwd=folder,
                       check=False, capture_output=True)
    return folder


def _run(code: Path, template: str, out: Path, neutral: Path) -> dict:
    """One study in a child process: wall and CPU seconds, peak memory, the outcome."""
    env = dict(os.environ, PYTHONPATH=str(code))
    log = out.with_suffix(".log")
    start = time.perf_counter()
    with open(log, "w", encoding="utf-8") as sink:
        child = subprocess.Popen([sys.executable, "-c", RUN, "study", template, "-o", str(out),
                                  "-q"], cwd=neutral, env=env, stdout=sink, stderr=sink)
        # this child's own resource use (its forked helpers' included once they are reaped)
        _, status, usage = os.wait4(child.pid, 0)
        child.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - start
    record = {"returncode": child.returncode, "wall_s": round(wall, 2),
              "user_s": round(usage.ru_utime, 2), "system_s": round(usage.ru_stime, 2),
              "peak_mb": round(usage.ru_maxrss / 1024.0, 1),
              "summary": log.read_text(encoding="utf-8").strip().splitlines()[-1:]}
    study = out / "study.json"
    if study.exists():
        data = json.loads(study.read_text(encoding="utf-8"))
        record["recommended"] = data.get("recommended")
        record["feasible"] = sorted(c["name"] for c in data["candidates"] if c.get("feasible"))
    return record


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", required=True, help="the earlier commit")
    parser.add_argument("--template", default="stadium")
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args(argv)
    runs: dict[str, list[dict]] = {"before": [], "now": []}
    with tempfile.TemporaryDirectory(prefix="fabplan-bench-study-") as tmp:
        folder = Path(tmp)
        earlier = checkout(args.against, folder / "earlier")
        neutral = folder / "run"
        neutral.mkdir()
        load_before = f"{os.getloadavg()[0]:.2f}"
        try:
            for k in range(args.rounds):
                for name, code in (("before", earlier), ("now", ROOT)):
                    record = _run(code, args.template, folder / f"{name}-{k}", neutral)
                    runs[name].append(record)
                    print(f"round {k + 1} {name}: {record['wall_s']} s wall, {record['user_s']} s "
                          f"user, recommended {record.get('recommended')}", flush=True)
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(earlier)],
                           check=False, capture_output=True)
    load_after = f"{os.getloadavg()[0]:.2f}"
    medians = {name: statistics.median(r["wall_s"] for r in rs) for name, rs in runs.items()}
    print(f"\n1-minute load before {load_before}, after {load_after}\n")
    print("| code | wall time [s] | median [s] | user CPU [s] | recommended |")
    print("|---|---|---|---|---|")
    for name, label in (("before", args.against), ("now", "this checkout")):
        rs = runs[name]
        print(f"| {label} | {', '.join(str(r['wall_s']) for r in rs)} | {medians[name]:.1f} | "
              f"{', '.join(str(r['user_s']) for r in rs)} | {rs[-1].get('recommended')} |")
    print(f"\nratio of the medians: {medians['now'] / medians['before']:.2f}")
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / f"study-{args.template}-{datetime.date.today().isoformat()}.json"
    path.write_text(json.dumps({"template": args.template, "against": args.against,
                                "load": [load_before, load_after], "runs": runs,
                                "median_wall_s": medians}, indent=1), encoding="utf-8")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

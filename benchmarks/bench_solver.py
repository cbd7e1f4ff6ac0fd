"""Solver benchmark: seconds per iteration, iterations, peak memory and where the time goes.

Run from the repository root::

    python benchmarks/bench_solver.py                       # bundled net + 3k, 10k, 30k, 100k
    python benchmarks/bench_solver.py --quick               # bundled net + 10k only
    python benchmarks/bench_solver.py --sizes 10000 30000 --profile wein99 weingarten-173x173

Each case runs in its own Python process, so its resident peak (``ru_maxrss`` of that
process) is its own. Cases:

- ``wein99``: the bundled 1,732-vertex linear Weingarten net, every vertex moved by
  seeded noise of 1% of the mean edge, optimized with ``linear-weingarten``.
- ``weingarten-MxM`` (one per ``--sizes`` entry, ``M = round(sqrt(size))``): an exact
  linear Weingarten net of revolution from `fabplan.net.generate.rotational_weingarten_snet`
  (angle 80 degrees like the bundled net's 80.2, Meusnier radius 3 at a unit neck:
  negative Gaussian curvature, like most of the bundled net), perturbed the same way and
  optimized with ``linear-weingarten``. A rotational S-net on a given profile is not
  isogonal with constant radius in general; this one's meridian is built so that it is,
  so the perturbed net has a linear Weingarten solution within 1% of an edge, as the
  bundled one does. (The isogonal sphere net would do too, but it is degenerate: on a
  sphere the radius condition repeats the sphere condition, and the solver then creeps
  near its tolerance.)

Timings come from the solver's own `IterationRecord` (assembly = everything before the
factorization: footpoints, residuals, Jacobians, normal equations). The median is taken
over the iterations that solved a linear system. The results are printed as a markdown
table and written as JSON to ``benchmarks/results/solver-<date>.json``; ``--profile``
writes a cProfile listing of a case's whole `fabplan.optimize` call, sorted by cumulative
time, to ``benchmarks/results/profile-<case>-<date>.txt``.
"""

from __future__ import annotations

import argparse
import cProfile
import datetime
import io
import json
import math
import os
import platform
import pstats
import resource
import subprocess
import sys
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"

# Targets on this 2-core machine: (vertices at most, seconds per iteration, peak GB).
TARGETS = [
    (2_000, 0.05, None),        # the bundled 1,732-vertex net
    (120_000, 3.0, 6.0),        # about 100k vertices
]

NOISE = 0.01       # of the mean edge length
SEED = 0
ANGLE_DEG = 80.0   # of the generated nets
RADIUS = 3.0       # Meusnier radius of the generated nets (unit neck radius)
NET = "linear-weingarten"


def target_for(vertices: int) -> tuple[float | None, float | None]:
    """(seconds per iteration, peak GB) targets for a net of this size, None where none."""
    if vertices <= TARGETS[0][0]:
        return TARGETS[0][1], TARGETS[0][2]
    if 80_000 <= vertices <= TARGETS[1][0]:
        return TARGETS[1][1], TARGETS[1][2]
    return None, None


def case_names(sizes: list[int]) -> list[str]:
    names = ["wein99"]
    for size in sizes:
        m = round(math.sqrt(size))
        names.append(f"weingarten-{m}x{m}")
    return names


# ---------------------------------------------------------------------------- worker side
def _noisy(mesh, fraction: float, seed: int):
    """Every vertex moved by a seeded random vector of length `fraction` x mean edge."""
    import numpy as np

    rng = np.random.default_rng(seed)
    d = rng.normal(size=mesh.vertices.shape)
    d *= fraction * mesh.mean_edge_length / np.linalg.norm(d, axis=1, keepdims=True)
    return mesh.with_vertices(mesh.vertices + d)


def _build(name: str):
    import fabplan
    from fabplan.net.generate import rotational_snet, rotational_weingarten_snet

    if name == "wein99":
        return fabplan.QuadMesh.from_obj(fabplan.data_path("wein99.obj"))
    kind, size = name.split("-")
    m, k = (int(v) for v in size.split("x"))
    if kind == "sphere":  # the degenerate alternative, kept for comparison
        return rotational_snet(m, k, profile="sphere", angle_deg=ANGLE_DEG, isogonal=True)
    return rotational_weingarten_snet(m, k, radius=RADIUS, angle_deg=ANGLE_DEG)


def _peak_gb() -> float:
    """Resident peak of this process (ru_maxrss is in kB on Linux, bytes on macOS)."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / (1 << 30) if sys.platform == "darwin" else peak / (1 << 20)


def _median(values: list[float]) -> float | None:
    values = sorted(values)
    if not values:
        return None
    mid = len(values) // 2
    return values[mid] if len(values) % 2 else (values[mid - 1] + values[mid]) / 2


def _timing_hooks() -> dict:
    """Time the set-up and the numeric factorizations from outside the solver, the same way
    on this checkout and on older ones: the solver's pattern construction
    (`GuidedProjection._build_pattern`), each linear solver's first factorization (symbolic
    analysis and its matrices) and CHOLMOD's numeric factorizations. Lists of seconds, and
    the unknowns of every numeric factorization (``numeric_unknowns``: a multilevel solve
    factors its coarse nets' systems too)."""
    from fabplan.solve import linalg
    from fabplan.solve import solver as solver_module

    times: dict = {"pattern": [], "analysis": [], "numeric": [], "numeric_unknowns": []}

    def timed(function, into: str):
        def wrapper(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                times[into].append(time.perf_counter() - t0)
        return wrapper

    solver_class = solver_module.GuidedProjection
    solver_class._build_pattern = timed(solver_class._build_pattern, "pattern")
    try:
        from cvxopt import cholmod
    except ImportError:
        cholmod = None
    else:
        numeric = timed(cholmod.numeric, "numeric")

        def sized(matrix, *args):
            times["numeric_unknowns"].append(matrix.size[0])
            return numeric(matrix, *args)
        cholmod.numeric = sized
    factor = linalg.SparseSPDSolver.factor
    analysed: set = set()

    def first_factor_timed(self, upper):
        if id(self) in analysed:
            return factor(self, upper)
        analysed.add(id(self))
        before, t0 = len(times["numeric"]), time.perf_counter()
        try:
            return factor(self, upper)
        finally:
            numeric = sum(times["numeric"][before:])
            times["analysis"].append(time.perf_counter() - t0 - numeric)

    linalg.SparseSPDSolver.factor = first_factor_timed
    return times


def run_case(name: str, profile: bool = False, max_iterations: int | None = None,
             backend: str = "auto", multilevel: bool | None = None) -> dict:
    """Generate, perturb and optimize one case in this process; the record of the run.
    `multilevel`: `SolverSettings.multilevel` (None: the solver's default)."""
    import numpy as np

    import fabplan
    from fabplan.solve.solver import SolverSettings

    t0 = time.perf_counter()
    net = _build(name)
    start = _noisy(net, NOISE, SEED)
    setup_seconds = time.perf_counter() - t0
    before_gb = _peak_gb()
    settings = SolverSettings(backend=backend)
    if multilevel is not None:
        settings.multilevel = multilevel
    hooks = _timing_hooks()
    if max_iterations is not None:
        settings.max_iterations = max_iterations
    profiler = cProfile.Profile() if profile else None
    t1, cpu1 = time.perf_counter(), time.process_time()
    if profiler:
        profiler.enable()
    result = fabplan.optimize(start, NET, settings=settings)
    if profiler:
        profiler.disable()
    wall, cpu = time.perf_counter() - t1, time.process_time() - cpu1
    steps = [h for h in result.history if h["step"] > 0]
    props = result.properties
    L = result.mesh.mean_edge_length
    # the full net's numeric factorizations (not those of a multilevel solve's coarse nets)
    unknowns = hooks["numeric_unknowns"]
    full = max(unknowns, default=0)
    numeric = [t for t, n in zip(hooks["numeric"], unknowns, strict=True) if n == full]
    median_iteration = _median([h["seconds"] for h in steps])
    record = {
        "case": name,
        "fabplan": str(Path(fabplan.__file__).resolve().parent),
        "net": NET,
        "vertices": net.vertex_count,
        "stars": int(len(net.stars)),
        "backend": result.linear_solver,
        "status": result.status,
        "iterations": result.iterations,
        "median_iteration_seconds": median_iteration,
        "first_iteration_seconds": steps[0]["seconds"] if steps else None,
        "median_assembly_seconds": _median([h["assembly_seconds"] for h in steps]),
        "median_factor_seconds": _median([h["factor_seconds"] for h in steps]),
        "median_solve_seconds": _median([h["solve_seconds"] for h in steps]),
        "share": {k: sum(h[f"{k}_seconds"] for h in steps) / max(sum(h["seconds"] for h in steps), 1e-300)
                  for k in ("assembly", "factor", "solve")},
        "solver_seconds": result.seconds,
        # set-up: the normal equations' pattern, plus the first factorization's symbolic
        # analysis and matrices (that factorization's numeric part not counted)
        "setup_seconds": sum(hooks["pattern"]) + sum(hooks["analysis"]),
        "pattern_seconds": sum(hooks["pattern"]),
        "analysis_seconds": sum(hooks["analysis"]),
        # CHOLMOD's numeric factorizations alone (None with another backend)
        "median_numeric_seconds": _median(numeric),
        "numeric_seconds": numeric,
        "iteration_over_numeric": (median_iteration / _median(numeric)
                                   if numeric and median_iteration else None),
        "linear_algebra_over_numeric": (
            _median([h["assembly_seconds"] + h["factor_seconds"] + h["solve_seconds"] for h in steps])
            / _median(numeric) if numeric and steps else None),
        # set-up in iterations: pattern, symbolic analysis and the first assembly, over
        # the median iteration
        "setup_iterations": ((sum(hooks["pattern"]) + sum(hooks["analysis"])
                              + steps[0]["assembly_seconds"]) / median_iteration
                             if steps and median_iteration else None),
        # the whole solve's seconds (set-up and coarse levels included) until the hard
        # residual first came below 1e-6 and 1e-10 (None: never)
        "seconds_to": {tol: _seconds_to(result, float(tol)) for tol in ("1e-6", "1e-10")},
        "optimize_wall_seconds": wall,
        # about 1 when the run had a core to itself (the solver's work is single-threaded);
        # well below 1 when other processes competed for the CPUs
        "cpu_per_wall": cpu / wall,
        # optimize's work outside the iterations: reference surface, pattern, measuring
        "outside_iterations_seconds": wall - sum(h["seconds"] for h in result.history),
        "generate_seconds": setup_seconds,
        "peak_rss_gb": _peak_gb(),
        "peak_rss_before_optimize_gb": before_gb,
        "final_hard_residual": result.history[-1]["hard_residual"],
        "sphere_residual_relative_max": props["sphere_residual_relative"]["max"],
        "radius_spread_relative": float(np.ptp([props["meusnier_radius"]["min"],
                                                props["meusnier_radius"]["max"]])
                                        / props["meusnier_radius"]["mean"]),
        "angle_spread_deg": props["intersection_angle_deg"]["max"] - props["intersection_angle_deg"]["min"],
        "mean_displacement_relative": float(
            np.linalg.norm(result.mesh.vertices - start.vertices, axis=1).mean() / L),
        # how far the result lies from the net before the noise (the exact solution of the
        # generated cases), in mean edges
        "off_unperturbed_relative": {k: float(f(np.linalg.norm(result.mesh.vertices - net.vertices,
                                                              axis=1)) / L)
                                     for k, f in (("max", np.max), ("mean", np.mean))},
        "angle_deg": result.parameters.get("angle_deg"),
        "radius": result.parameters.get("radius"),
        # the coarse nets solved first (`SolverSettings.multilevel`), coarsest first; None
        # for a plain solve (and for code without the multilevel start)
        "multilevel": result.parameters.get("multilevel"),
        "multilevel_setting": multilevel,
        "history": result.history,
    }
    if profiler:
        out = io.StringIO()
        stats = pstats.Stats(profiler, stream=out).sort_stats("cumulative")
        stats.print_stats(40)
        # what one solver run spends its time on, call by call
        stats.print_callees(r"solver.py:\d+\(run\)")
        record["profile"] = out.getvalue()
    return record


def _seconds_to(result, tolerance: float) -> float | None:
    """Seconds of `result`'s whole solve until its hard residual was first at most
    `tolerance`: the solve's time less that of the iterations after that point."""
    history = result.history
    reached = [i for i, h in enumerate(history) if h["hard_residual"] <= tolerance]
    if not reached:
        return None
    return result.seconds - sum(h["seconds"] for h in history[reached[0] + 1:])


# ---------------------------------------------------------------------------- driver side
def run_in_subprocess(name: str, profile: bool, max_iterations: int | None,
                      timeout: float | None, backend: str = "auto",
                      package: Path | None = None, multilevel: str = "auto") -> dict:
    """Run one case in a new Python process; `package`: the checkout whose fabplan it
    imports (default: this one); `multilevel`: "auto", "on" or "off"."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", name, "--backend", backend,
           "--multilevel", multilevel]
    root = str(package or Path(__file__).resolve().parent.parent)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [root] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]))
    if profile:
        cmd.append("--worker-profile")
    if max_iterations is not None:
        cmd += ["--max-iterations", str(max_iterations)]
    load = os.getloadavg()[0]  # a busy neighbour process slows every number down
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env)
    except subprocess.TimeoutExpired:
        return {"case": name, "status": f"timeout after {timeout:g} s"}
    if proc.returncode != 0:
        return {"case": name, "status": "failed", "error": proc.stderr.strip().splitlines()[-5:],
                "process_seconds": time.perf_counter() - t0}
    record = json.loads(proc.stdout.strip().splitlines()[-1])
    record["process_seconds"] = time.perf_counter() - t0
    record["load_average_before"] = load
    record["load_average_after"] = os.getloadavg()[0]
    return record


def comparison_table(records: list[dict]) -> str:
    """One line per run of `--compare`: set-up, iteration, factorization and whole solve."""
    head = ("| case | vertices | code | run | iterations | set-up s (pattern + analysis) "
            "| set-up / iteration | s / iteration | numeric factorization s "
            "| iteration / factorization | assembly + factor + solve / factorization "
            "| s to 1e-6 / 1e-10 | whole solve s | final hard residual | peak RSS GB "
            "| load before / after |")
    lines = [head, "|" + "|".join(["---"] * (head.count("|") - 1)) + "|"]
    for r in records:
        if "median_iteration_seconds" not in r:
            lines.append(f"| {r['case']} | | {r.get('code', '')} | {r.get('run', '')} | "
                         f"{r['status']} | | | | | | | | | | | |")
            continue
        to = r.get("seconds_to") or {}
        lines.append(
            f"| {r['case']} | {r['vertices']:,} | {r['code']} | {r['run']} | {r['iterations']} "
            f"| {r['setup_seconds']:.2f} ({r['pattern_seconds']:.2f} + {r['analysis_seconds']:.2f}) "
            f"| {_fmt(r.get('setup_iterations'), '.1f')} "
            f"| {_fmt(r['median_iteration_seconds'], '.3f')} "
            f"| {_fmt(r['median_numeric_seconds'], '.3f')} "
            f"| {_fmt(r['iteration_over_numeric'], '.2f')} "
            f"| {_fmt(r['linear_algebra_over_numeric'], '.2f')} "
            f"| {_fmt(to.get('1e-6'), '.2f')} / {_fmt(to.get('1e-10'), '.2f')} "
            f"| {r['solver_seconds']:.2f} | {r['final_hard_residual']:.3e} "
            f"| {r['peak_rss_gb']:.2f} "
            f"| {r['load_average_before']:.2f} / {r['load_average_after']:.2f} |")
    return "\n".join(lines)


def accuracy_table(records: list[dict]) -> str:
    """One line per run: iterations on the full net and on the coarse nets, whole solve,
    and the accuracy of the result."""
    head = ("| case | vertices | code | run | full-size iterations | coarse iterations (vertices) "
            "| whole solve s | sphere residual / edge | angle deg | radius "
            "| off the unperturbed net, max / mean (edges) | peak RSS GB |")
    lines = [head, "|" + "|".join(["---"] * (head.count("|") - 1)) + "|"]
    for r in records:
        if "median_iteration_seconds" not in r:
            continue
        off = r["off_unperturbed_relative"]
        lines.append(
            f"| {r['case']} | {r['vertices']:,} | {r.get('code', 'new')} | {r.get('run', 1)} "
            f"| {r['iterations']} | {_coarse(r)} | {r['solver_seconds']:.1f} "
            f"| {r['sphere_residual_relative_max']:.1e} | {_fmt(r['angle_deg'], '.5f')} "
            f"| {_fmt(r['radius'], '.5f')} | {off['max']:.2e} / {off['mean']:.2e} "
            f"| {r['peak_rss_gb']:.2f} |")
    return "\n".join(lines)


def _coarse(record: dict) -> str:
    """The coarse levels of a multilevel solve: ``5 (25,281) + 8 (6,400)``, finest first."""
    levels = (record.get("multilevel") or {}).get("levels", [])
    return " + ".join(f"{level['iterations']} ({level['vertices']:,})"
                      for level in reversed(levels)) or "none"


def _fmt(value, spec: str, missing: str = "n/a") -> str:
    return missing if value is None else format(value, spec)


def markdown_table(records: list[dict]) -> str:
    head = ("| case | vertices | backend | status | iterations | s / iteration (target) "
            "| assembly / factor / solve | first iteration s | peak RSS GB (target) "
            "| final sphere residual / edge | CPU / wall |")
    lines = [head, "|" + "|".join(["---"] * (head.count("|") - 1)) + "|"]
    for r in records:
        if "median_iteration_seconds" not in r:
            lines.append(f"| {r['case']} | | | {r['status']} | | | | | | | |")
            continue
        t_iter, t_mem = target_for(r["vertices"])
        share = r["share"]
        ok_iter = "" if t_iter is None else (
            f" ({'<=' if r['median_iteration_seconds'] <= t_iter else 'MISSES'} {t_iter:g})")
        ok_mem = "" if t_mem is None else (
            f" ({'<=' if r['peak_rss_gb'] <= t_mem else 'MISSES'} {t_mem:g})")
        lines.append(
            f"| {r['case']} | {r['vertices']:,} | {r['backend']} | {r['status']} | {r['iterations']} "
            f"| {_fmt(r['median_iteration_seconds'], '.3f')}{ok_iter} "
            f"| {share['assembly']:.0%} / {share['factor']:.0%} / {share['solve']:.0%} "
            f"({_fmt(r['median_assembly_seconds'], '.3f')} / {_fmt(r['median_factor_seconds'], '.3f')} / "
            f"{_fmt(r['median_solve_seconds'], '.3f')} s) "
            f"| {_fmt(r['first_iteration_seconds'], '.2f')} "
            f"| {r['peak_rss_gb']:.2f}{ok_mem} | {r['sphere_residual_relative_max']:.1e} "
            f"| {r['cpu_per_wall']:.2f} |")
    return "\n".join(lines)


def _git(root: Path, *args: str) -> str | None:
    try:
        return subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True,
                              timeout=30).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None


def environment() -> dict:
    import numpy
    import scipy

    import fabplan

    root = Path(fabplan.__file__).resolve().parent.parent

    def git(*args):
        return _git(root, *args)

    return {
        "date": datetime.datetime.now().isoformat(timespec="seconds"),
        "command": " ".join([Path(sys.executable).name, *sys.argv]),
        "machine": platform.machine(),
        "cpus": os.cpu_count(),
        "python": platform.python_version(),
        "numpy": numpy.__version__,
        "scipy": scipy.__version__,
        "fabplan": str(root),
        "git_commit": git("rev-parse", "HEAD"),
        "git_uncommitted_package_files": git("status", "--porcelain", "--", "fabplan"),
        "noise_fraction_of_mean_edge": NOISE,
        "seed": SEED,
        "net": NET,
        "generated_nets": f"rotational_weingarten_snet(M, M, radius={RADIUS:g}, "
                          f"angle_deg={ANGLE_DEG:g})",
        "targets": [{"max_vertices": v, "seconds_per_iteration": s, "peak_gb": g}
                    for v, s, g in TARGETS],
    }


def _write_atomically(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="*", default=None,
                        help="approximate vertex counts of the generated nets "
                             "(default 3000 10000 30000 100000)")
    parser.add_argument("--quick", action="store_true",
                        help="bundled net and a 10k net only (unless --sizes is given)")
    parser.add_argument("--cases", nargs="*", default=[], metavar="CASE",
                        help="more cases by name: weingarten-MxM, or sphere-MxM for the "
                             "isogonal sphere net")
    parser.add_argument("--profile", nargs="*", default=[], metavar="CASE",
                        help="also run these cases under cProfile (e.g. wein99 weingarten-173x173)")
    parser.add_argument("--max-iterations", type=int, default=None)
    parser.add_argument("--timeout", type=float, default=None, help="seconds per case")
    parser.add_argument("--backend", default="auto",
                        help="linear solver backend: auto, pardiso, cholmod or superlu")
    parser.add_argument("--output", type=Path, default=None, help="JSON file to write")
    parser.add_argument("--compare", type=Path, default=None, metavar="CHECKOUT",
                        help="also run every case with the fabplan package of CHECKOUT (an older "
                             "commit's tree), alternating with this one; a side-by-side table")
    parser.add_argument("--repeat", type=int, default=1,
                        help="rounds of --compare (each round runs both codes once per case)")
    parser.add_argument("--first", choices=["new", "old"], default="new",
                        help="the code that runs first in odd rounds of --compare")
    parser.add_argument("--multilevel", choices=["auto", "on", "off"], default="auto",
                        help="SolverSettings.multilevel: auto (the solver's default, from 20k "
                             "vertices), on, or off (the plain solve on the full net, to "
                             "measure its set-up and iterations)")
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    parser.add_argument("--worker-profile", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)

    if args.worker:
        multilevel = {"auto": None, "on": True, "off": False}[args.multilevel]
        record = run_case(args.worker, args.worker_profile, args.max_iterations, args.backend,
                          multilevel)
        print(json.dumps(record))
        return 0

    sizes = args.sizes if args.sizes is not None else ([10_000] if args.quick else
                                                       [3_000, 10_000, 30_000, 100_000])
    names = case_names(sizes) + [n for n in args.cases if n not in case_names(sizes)]
    env = environment()
    print(f"fabplan at {env['fabplan']} (commit {str(env['git_commit'])[:10]}"
          f"{', uncommitted changes' if env['git_uncommitted_package_files'] else ''}), "
          f"{env['cpus']} CPUs, net {NET}, noise {NOISE:.0%} of the mean edge", flush=True)
    records = []
    codes = [("new", None)] + ([("old", args.compare.resolve())] if args.compare else [])
    if args.first == "old":
        codes.reverse()
    for round_ in range(1, (args.repeat if args.compare else 1) + 1):
        for name in names:
            # alternate which code runs first, so that neither always finds the machine warm
            for code, package in (codes if round_ % 2 else codes[::-1]):
                print(f"running {name}{f' ({code}, round {round_})' if args.compare else ''} ...",
                      flush=True)
                records.append(run_in_subprocess(name, False, args.max_iterations, args.timeout,
                                                 args.backend, package, args.multilevel))
                r = records[-1]
                r["code"], r["run"] = code, round_
                print(f"  {r['status']}, {r.get('iterations')} iterations, "
                      f"set-up {_fmt(r.get('setup_seconds'), '.2f')} s, "
                      f"{_fmt(r.get('median_iteration_seconds'), '.3f')} s/iteration, "
                      f"peak {_fmt(r.get('peak_rss_gb'), '.2f')} GB", flush=True)
    profiles = {}
    for name in args.profile:
        print(f"profiling {name} ...", flush=True)
        r = run_in_subprocess(name, True, args.max_iterations, args.timeout, args.backend,
                              multilevel=args.multilevel)
        if "profile" in r:
            profiles[name] = r["profile"]
            stamp = datetime.date.today().isoformat()
            _write_atomically(RESULTS / f"profile-{name}-{stamp}.txt", r["profile"])
            print(r["profile"], flush=True)
        else:
            print(f"  {r['status']}", flush=True)

    table = markdown_table([r for r in records if r["code"] == "new"] if args.compare else records)
    table += "\n\n" + accuracy_table(records)
    if args.compare:
        table += "\n\n" + comparison_table(records)
        env["compare"] = {"old": str(args.compare.resolve()),
                          "old_commit": _git(args.compare.resolve(), "rev-parse", "HEAD")}
    print()
    print(table)
    print()
    print("Targets: <= 0.05 s per iteration on the bundled 1,732-vertex net; <= 3 s per iteration"
          " and <= 6 GB peak at 100k vertices (2-core machine).")
    suffix = "-quick" if args.quick and args.sizes is None else ""
    out = args.output or RESULTS / f"solver-{datetime.date.today().isoformat()}{suffix}.json"
    _write_atomically(out, json.dumps({"environment": env, "table": table, "cases": records,
                                       "profiles": profiles}, indent=1))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

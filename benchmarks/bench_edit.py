"""Live editing through the scripting interface of `fabplan edit` (docs/edit.md).

One handle is dragged half an edge per step for 100 steps, along the surface normal at
it, out to two edges and back (a triangle wave, as a hand drags to and fro), each step a
``POST /api/drag`` that returns the solved net. Measured: solved updates per second
sustained (wall time of the requests, HTTP and JSON included), the CPU time per update
(client and server, one process), the same drags on a session without HTTP (the solver's
rate and CPU time), whether every update was
accepted (converged to the tolerance, 1e-6 of a mean edge, and neither folded nor
crumpled), and the worst residual. Nets: the bundled wein99 (1,732 vertices) as an
S-net, and a 100 x 100 linear Weingarten net of revolution (10,000 vertices) as an S-net.

    python benchmarks/bench_edit.py [--steps 100] [--cases wein99 rot100] [--profile]
"""

from __future__ import annotations

import argparse
import cProfile
import json
import pstats
import sys
import time
import urllib.request
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import fabplan  # noqa: E402
from fabplan.edit.server import EditServer  # noqa: E402
from fabplan.edit.session import EditOptions, EditSession  # noqa: E402
from fabplan.net.geometry import canonical_stars, star_normals  # noqa: E402


def case(name: str) -> fabplan.QuadMesh:
    if name == "wein99":
        return fabplan.QuadMesh.from_obj(fabplan.data_path("wein99.obj"))
    from fabplan.net.generate import rotational_weingarten_snet

    m = int(name.removeprefix("rot"))
    return rotational_weingarten_snet(m, m, radius=3.0, angle_deg=80.0)


def post(server: EditServer, path: str, body: dict) -> dict:
    request = urllib.request.Request(
        f"http://127.0.0.1:{server.port}{path}", data=json.dumps(body).encode(), method="POST",
        headers={"X-Fabplan-Token": server.token, "Content-Type": "application/json"})
    with urllib.request.urlopen(request, timeout=600) as response:
        return json.loads(response.read())


def run(name: str, steps: int, profile: bool) -> dict:
    mesh = case(name)
    stars = canonical_stars(mesh.vertices, mesh.stars)
    # the interior vertex farthest from the boundary
    interior = np.flatnonzero(mesh.star_of_vertex >= 0)
    boundary = mesh.vertices[mesh.is_boundary_vertex]
    far = [np.min(np.linalg.norm(boundary - mesh.vertices[v], axis=1)) for v in interior]
    vid = int(interior[int(np.argmax(far))])
    normal = star_normals(mesh.vertices, stars)[mesh.star_of_vertex[vid]]
    half = 0.5 * mesh.mean_edge_length
    t0 = time.perf_counter()
    server = EditServer(EditSession(mesh, EditOptions("snet")), None).start()
    opened = time.perf_counter() - t0
    start = np.array(post(server, "/api/drag", {"handles": [vid], "targets": [
        mesh.vertices[vid].tolist()]})["positions"][vid])
    k, way, path = 0, 1, []
    for _ in range(steps):
        k += way
        if abs(k) == 4:
            way = -way
        path.append(k)
    profiler = cProfile.Profile() if profile else None
    answers, seconds = [], []
    c0 = time.process_time()
    t0 = time.perf_counter()
    if profiler:
        profiler.enable()
    for k in path:
        s = time.perf_counter()
        answers.append(post(server, "/api/drag", {"handles": [vid],
                                                  "targets": [(start + k * half * normal).tolist()]}))
        seconds.append(time.perf_counter() - s)
    if profiler:
        profiler.disable()
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0
    server.stop()
    server.join(30)
    # the same drags on a session of its own, without HTTP: the solver's rate, and the CPU
    # time per update, which other jobs on the machine inflate less than the wall time
    session = EditSession(mesh, EditOptions("snet"))
    session.drag({vid: mesh.vertices[vid]})
    c1, t1 = time.process_time(), time.perf_counter()
    direct = [session.drag({vid: start + k * half * normal}).result for k in path]
    direct_wall, direct_cpu = time.perf_counter() - t1, time.process_time() - c1
    accepted = [a["accepted"] for a in answers]
    out = {
        "case": name, "vertices": mesh.vertex_count, "handle": vid, "steps": steps,
        "updates_per_second": steps / wall, "accepted": int(sum(accepted)),
        "max_residual_mean_edges": max(a["residual"] for a in answers),
        "median_update_seconds": float(np.median(seconds)),
        "max_update_seconds": float(np.max(seconds)),
        "median_solve_seconds": float(np.median([a["seconds"] for a in answers])),
        "mean_iterations": float(np.mean([a["iterations"] for a in answers])),
        "statuses": {s: sum(a["status"] == s for a in answers) for s in {a["status"] for a in answers}},
        "session_open_seconds": opened,
        "cpu_ms_per_update": 1000 * cpu / steps,
        "solver_only_updates_per_second": steps / direct_wall,
        "solver_only_cpu_ms_per_update": 1000 * direct_cpu / steps,
        "solver_only_accepted": int(sum(r.accepted for r in direct)),
    }
    if profiler:
        stats = pstats.Stats(profiler)
        stats.sort_stats("cumulative").print_stats(25)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--cases", nargs="+", default=["wein99", "rot100"])
    parser.add_argument("--profile", action="store_true", help="profile the drags (cProfile)")
    parser.add_argument("--output", help="JSON file for the results")
    args = parser.parse_args(argv)
    results = []
    for name in args.cases:
        r = run(name, args.steps, args.profile)
        results.append(r)
        print(f"{r['case']}: {r['vertices']} vertices, {r['updates_per_second']:.2f} updates/s, "
              f"{r['accepted']}/{r['steps']} accepted, worst residual "
              f"{r['max_residual_mean_edges']:.1e} edges, {r['mean_iterations']:.2f} iterations, "
              f"median update {1000 * r['median_update_seconds']:.0f} ms "
              f"(solve {1000 * r['median_solve_seconds']:.0f} ms), {r['statuses']}, "
              f"CPU {r['cpu_ms_per_update']:.0f} ms per update; without HTTP "
              f"{r['solver_only_updates_per_second']:.2f} updates/s, CPU "
              f"{r['solver_only_cpu_ms_per_update']:.0f} ms per update, "
              f"{r['solver_only_accepted']}/{r['steps']} accepted", flush=True)
    if args.output:
        Path(args.output).write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

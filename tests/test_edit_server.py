"""The live editor's server (`fabplan edit`): its scripting API, coalesced drags, failing
solves, the token and origin checks, saving and reopening, and its shutdown.

The nets it answers with are checked by code of this file: every star's five vertices on
one sphere (or plane) within 1e-6 of an edge, the handle at its target, no face turned
over against its neighbours.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest

import fabplan

pytest.importorskip("starlette", reason="the edit extra is missing: pip install -e '.[edit]'")
pytest.importorskip("uvicorn")
ws_client = pytest.importorskip("websockets.sync.client")

from websockets.exceptions import ConnectionClosed, InvalidHandshake  # noqa: E402

from fabplan.edit.server import LAST_PAGE_GRACE_SECONDS, EditServer  # noqa: E402
from fabplan.edit.session import EditOptions, EditSession  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


# ------------------------------------------------------------------ checks of our own
def sphere_misses(X: np.ndarray, stars: np.ndarray) -> np.ndarray:
    """(s,) float, for each star the largest distance of its five vertices from the sphere
    (or plane) through them, to first order: the smallest singular vector of the rows
    (|p|^2, p, 1) gives the sphere's coefficients, and |f(p)| / |grad f(p)| the distance."""
    P = X[stars] - X[stars[:, :1]]
    scale = np.linalg.norm(P[:, 1:], axis=2).mean(axis=1)
    Q = P / scale[:, None, None]
    rows = np.concatenate([np.sum(Q * Q, axis=2)[..., None], Q, np.ones_like(Q[..., :1])], axis=2)
    u = np.linalg.svd(rows)[2][:, -1, :]
    f = np.einsum("spk,sk->sp", rows, u)
    grad = 2 * u[:, None, :1] * Q + u[:, None, 1:4]
    return (np.abs(f) / np.linalg.norm(grad, axis=2)).max(axis=1) * scale


def regular_stars(faces: list[list[int]], n: int) -> np.ndarray:
    """(s, 5) int, interior vertices of valence 4 in four quads with their neighbours."""
    neighbours: list[set] = [set() for _ in range(n)]
    count = np.zeros(n, int)
    for f in faces:
        for i, v in enumerate(f):
            neighbours[v].update((f[i - 1], f[(i + 1) % len(f)]))
            count[v] += 1
    return np.array([[v, *sorted(neighbours[v])] for v in range(n)
                     if count[v] == 4 and len(neighbours[v]) == 4])


def folded_edges(X: np.ndarray, faces: list[list[int]]) -> int:
    """Interior edges across which the two faces' normals (Newell) point apart."""
    normals = []
    for f in faces:
        p = X[f]
        normals.append(np.cross(p, np.roll(p, -1, axis=0)).sum(axis=0))
    normals = np.array(normals)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    sides: dict = {}
    for k, f in enumerate(faces):
        for i in range(len(f)):
            sides.setdefault(frozenset((f[i], f[(i + 1) % len(f)])), []).append(k)
    pairs = np.array([p for p in sides.values() if len(p) == 2])
    return int(np.sum(np.sum(normals[pairs[:, 0]] * normals[pairs[:, 1]], axis=1) < 0))


def mean_edge(X: np.ndarray, faces: list[list[int]]) -> float:
    lengths = [np.linalg.norm(X[f[i]] - X[f[(i + 1) % len(f)]]) for f in faces for i in range(len(f))]
    return float(np.mean(lengths))


def check_snet(X: np.ndarray, faces: list[list[int]]) -> None:
    misses = sphere_misses(X, regular_stars(faces, len(X)))
    assert misses.max() <= 1e-6 * mean_edge(X, faces), f"a star misses its sphere by {misses.max():.2e}"
    assert folded_edges(X, faces) == 0


# ------------------------------------------------------------------ a server
class Client:
    """Requests to a server the way a script sends them (urllib, the token as a header)."""

    def __init__(self, server: EditServer, token: str | None = None):
        self.server, self.token = server, server.token if token is None else token

    def request(self, path: str, body: dict | None = None, *, method: str | None = None,
                headers: dict | None = None) -> tuple[int, bytes]:
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(f"http://127.0.0.1:{self.server.port}{path}", data=data,
                                     method=method or ("POST" if body is not None else "GET"),
                                     headers={"X-Fabplan-Token": self.token,
                                              "Content-Type": "application/json", **(headers or {})})
        try:
            with urllib.request.urlopen(req, timeout=60) as response:
                return response.status, response.read()
        except urllib.error.HTTPError as exc:
            return exc.code, exc.read()

    def json(self, path: str, body: dict | None = None, **kw) -> dict:
        code, data = self.request(path, body, **kw)
        assert code == 200, data
        return json.loads(data)


@pytest.fixture
def served(wein99, tmp_path):
    server = EditServer(EditSession(wein99, EditOptions("snet")), tmp_path / "out.obj").start()
    yield server, Client(server)
    server.stop()
    server.join(20)


def _interior(mesh) -> int:
    return int(np.flatnonzero(mesh.star_of_vertex >= 0)[len(mesh.stars) // 2])


def _normal(mesh, vid: int) -> np.ndarray:
    from fabplan.net.geometry import canonical_stars, star_normals

    return star_normals(mesh.vertices, canonical_stars(mesh.vertices, mesh.stars))[mesh.star_of_vertex[vid]]


def test_a_drag_returns_a_solved_net_with_the_handle_at_its_target(served, wein99):
    server, client = served
    vid = _interior(wein99)
    target = wein99.vertices[vid] + 0.5 * wein99.mean_edge_length * _normal(wein99, vid)
    answer = client.json("/api/drag", {"handles": [vid], "targets": [target.tolist()]})
    assert answer["status"] == "converged" and answer["accepted"] and not answer["coalesced"]
    assert answer["residual"] <= 1e-6
    X = np.array(answer["positions"])
    assert np.array_equal(X[vid], target)
    net = client.json("/api/net")
    assert np.array_equal(np.array(net["positions"]), X)
    faces = net["faces"]
    check_snet(X, faces)
    # the net followed the handle, not the handle alone
    assert np.sum(np.linalg.norm(X - wein99.vertices, axis=1) > 0.01 * wein99.mean_edge_length) > 10
    obj = client.request("/api/net?format=obj")[1].decode()
    rows = np.array([[float(t) for t in line.split()[1:4]] for line in obj.splitlines()
                     if line.startswith("v ")])
    assert np.array_equal(rows, X)


def test_drags_that_arrive_while_a_solve_runs_are_coalesced(served, wein99):
    """Eight drags sent at once over the page's WebSocket: the first is solved, the ones
    waiting meanwhile are replaced by the latest, and the net ends at the last target."""
    server, client = served
    vid = _interior(wein99)
    start, n = wein99.vertices[vid], _normal(wein99, vid)
    steps = [start + 0.1 * k * wein99.mean_edge_length * n for k in range(1, 9)]
    before = server.session.seq
    url = f"ws://127.0.0.1:{server.port}/ws?token={server.token}"
    with ws_client.connect(url, origin=f"http://127.0.0.1:{server.port}") as ws:
        json.loads(ws.recv(timeout=60))                     # the state the page opens with
        for target in steps:
            ws.send(json.dumps({"type": "drag", "targets": {str(vid): target.tolist()},
                                "gesture": "g1"}))
        ws.send(json.dumps({"type": "release"}))
        deadline = time.time() + 60
        while time.time() < deadline:
            state = json.loads(ws.recv(timeout=60))
            if state["type"] == "state" and np.allclose(state["handles"].get(str(vid), start),
                                                        steps[-1], rtol=0, atol=0):
                break
        else:
            pytest.fail("the last drag never reached the page")
    solves = server.session.seq - before
    assert 1 <= solves <= 3, f"{solves} solves for 8 drags: they queued up"
    net = client.json("/api/net")
    X = np.array(net["positions"])
    assert np.array_equal(X[vid], steps[-1])
    check_snet(X, net["faces"])
    assert net["undo"] == 1          # one gesture, one step to undo


def test_concurrent_script_drags_get_the_result_that_replaced_them(served, wein99):
    import threading

    server, client = served
    vid = _interior(wein99)
    start, n = wein99.vertices[vid], _normal(wein99, vid)
    answers: dict = {}

    def drag(k: int) -> None:
        target = start + 0.1 * k * wein99.mean_edge_length * n
        answers[k] = client.json("/api/drag", {"handles": [vid], "targets": [target.tolist()],
                                               "positions": False})

    first = threading.Thread(target=drag, args=(1,))
    first.start()
    time.sleep(0.02)
    rest = [threading.Thread(target=drag, args=(k,)) for k in range(2, 8)]
    for t in rest:
        t.start()
    for t in [first, *rest]:
        t.join(120)
    solved = {json.dumps(a["targets"]) for a in answers.values()}
    assert len(solved) < len(answers), "every drag was solved: none was coalesced"
    for k, a in answers.items():
        mine = (start + 0.1 * k * wein99.mean_edge_length * n).tolist()
        assert a["coalesced"] == (a["targets"][str(vid)] != mine)
    final = np.array(client.json("/api/net")["positions"])[vid]
    assert any(np.array_equal(final, a["targets"][str(vid)]) for a in answers.values())


def test_a_failing_solve_returns_the_last_good_net_and_says_why(wein99, tmp_path):
    boundary = np.flatnonzero(wein99.is_boundary_vertex).tolist()
    session = EditSession(wein99, EditOptions("snet", max_seconds=20.0), pins=boundary)
    server = EditServer(session, tmp_path / "out.obj").start()
    try:
        client = Client(server)
        good = client.json("/api/net")["positions"]
        vid = _interior(wein99)
        far = wein99.vertices[vid] + [0.0, 0.0, 8 * wein99.mean_edge_length]
        answer = client.json("/api/drag", {"handles": [vid], "targets": [far.tolist()]})
        assert answer["status"] in ("not converged", "folded", "crumpled", "failed")
        assert not answer["accepted"] and answer["message"]
        assert answer["where"], "no place named where it fails"
        assert answer["positions"] == good
        assert client.json("/api/net")["positions"] == good
        state = client.json("/api/state")
        assert state["status"] == answer["status"] and state["message"] == answer["message"]
        # a drag it can follow goes on from the last good net
        near = np.array(good[vid]) + [0.0, 0.0, 0.1 * wein99.mean_edge_length]
        assert client.json("/api/drag", {"handles": [vid], "targets": [near.tolist()]})["accepted"]
    finally:
        server.stop()
        server.join(20)


def test_another_origin_is_refused(served):
    server, client = served
    code, text = client.request("/api/state", headers={"Origin": "http://example.com"})
    assert code == 403 and b"origin" in text
    code, _ = client.request("/api/drag", {"handles": [1], "targets": [[0, 0, 0]]},
                             headers={"Origin": "http://localhost:1"})
    assert code == 403
    # the server's own origin is let in
    assert client.request("/api/state", headers={"Origin": f"http://127.0.0.1:{server.port}"})[0] == 200
    # a rebinding: another host name for this address
    assert client.request("/api/state", headers={"Host": f"attacker.test:{server.port}"})[0] == 403
    url = f"ws://127.0.0.1:{server.port}/ws?token={server.token}"
    with pytest.raises((InvalidHandshake, ConnectionClosed)):
        with ws_client.connect(url, origin="http://example.com") as ws:
            ws.recv(timeout=10)
    assert server.session.seq == 0


def test_a_wrong_or_missing_token_is_refused(served):
    server, client = served
    for token in ("wrong", ""):
        code, text = Client(server, token).request("/api/state")
        assert code == 403 and b"token" in text
        assert Client(server, token).request("/", method="GET")[0] == 403
    url = f"ws://127.0.0.1:{server.port}/ws?token=wrong"
    with pytest.raises((InvalidHandshake, ConnectionClosed)):
        with ws_client.connect(url, origin=f"http://127.0.0.1:{server.port}") as ws:
            ws.recv(timeout=10)
    assert client.request("/", method="GET")[0] == 200


def test_save_writes_both_files_and_the_saved_net_reopens_with_its_handles(served, wein99, tmp_path):
    from fabplan.edit.record import read_saved

    server, client = served
    vid, pin = _interior(wein99), int(np.flatnonzero(wein99.is_boundary_vertex)[0])
    client.json("/api/role", {"vertex": pin, "role": "pin"})
    target = wein99.vertices[vid] + [0.0, 0.0, 0.3 * wein99.mean_edge_length]
    client.json("/api/drag", {"handles": [vid], "targets": [target.tolist()]})
    saved = client.json("/api/save", {})["saved"]
    assert saved == [str(tmp_path / "out.obj"), str(tmp_path / "out.json")]
    net = fabplan.QuadMesh.from_obj(tmp_path / "out.obj")
    assert np.array_equal(net.vertices[vid], target)
    check_snet(net.vertices, [f.tolist() for f in net.faces])
    record = json.loads((tmp_path / "out.json").read_text())
    assert record["status"] == "converged" and record["net"] == "snet"
    assert record["edit"]["handles"] == [{"vertex": vid, "position": target.tolist()}]
    assert record["edit"]["pins"] == [pin]
    assert [h["action"] for h in record["edit"]["history"]] == ["pin", "drag"]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".fabplan-")]
    again = read_saved(tmp_path / "out.obj")
    session = EditSession(net, EditOptions(**again.options), handles=again.handles, pins=again.pins,
                          history=again.history)
    assert sorted(session.handles) == [vid] and session.pins == {pin}
    assert np.array_equal(session.handles[vid], target)


def test_undo_redo_and_reset(served, wein99):
    server, client = served
    vid = _interior(wein99)
    opened = np.array(client.json("/api/net")["positions"])
    for dz in (0.2, 0.4):
        target = opened[vid] + [0.0, 0.0, dz * wein99.mean_edge_length]
        client.json("/api/drag", {"handles": [vid], "targets": [target.tolist()]})
    after = np.array(client.json("/api/net")["positions"])
    client.json("/api/undo", {})
    assert np.isclose(np.array(client.json("/api/net")["positions"])[vid, 2] - opened[vid, 2],
                      0.2 * wein99.mean_edge_length, rtol=0, atol=1e-12)
    client.json("/api/redo", {})
    assert np.array_equal(np.array(client.json("/api/net")["positions"]), after)
    client.json("/api/reset", {})
    state = client.json("/api/net")
    assert np.array_equal(np.array(state["positions"]), opened) and state["handles"] == {}


# ------------------------------------------------------------------ the command's end
def _start_cli(tmp_path: Path, *extra: str) -> tuple[subprocess.Popen, str]:
    code = "import sys; from fabplan.cli import main; sys.exit(main())"
    proc = subprocess.Popen(
        [sys.executable, "-c", code, "edit", str(fabplan.data_path("cmc1.obj")), "--net", "snet",
         "--no-open", "-o", str(tmp_path / "out.obj"), *extra],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)}, cwd=tmp_path)
    deadline = time.time() + 120
    assert proc.stdout is not None
    while time.time() < deadline:
        line = proc.stdout.readline()
        if "http://" in line:
            return proc, line.split()[-1]
        if proc.poll() is not None:
            break
    proc.kill()
    pytest.fail(f"the server did not start: {proc.stderr.read() if proc.stderr else ''}")


def _port_closed(url: str) -> bool:
    port = int(url.split(":")[2].split("/")[0])
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) != 0


def test_ctrl_c_ends_the_server_cleanly(tmp_path):
    proc, url = _start_cli(tmp_path)
    with urllib.request.urlopen(url, timeout=60) as page:      # serving
        assert b"fabplan edit" in page.read()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert "ended" in err and "Traceback" not in err
    assert _port_closed(url)
    assert sorted(p.name for p in tmp_path.iterdir()) == []      # nothing saved, nothing left


def test_closing_the_last_page_ends_the_server(tmp_path):
    proc, url = _start_cli(tmp_path)
    ws_url = url.replace("http://", "ws://").replace("/?token=", "/ws?token=")
    origin = url.split("/?")[0]
    with ws_client.connect(ws_url, origin=origin) as ws:
        assert json.loads(ws.recv(timeout=60))["type"] == "state"
        ws.send(json.dumps({"type": "save"}))
        assert json.loads(ws.recv(timeout=60))["type"] == "state"      # after the save
    t0 = time.time()
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert time.time() - t0 < LAST_PAGE_GRACE_SECONDS + 20
    assert "ended" in err and "Traceback" not in err
    assert _port_closed(url)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json", "out.obj"]


def test_the_shutdown_request_ends_the_server_and_its_worker(served):
    server, client = served
    worker = server.queue._thread
    assert client.json("/api/shutdown", {}) == {"stopping": True}
    server.join(20)
    assert not server._thread.is_alive() and not worker.is_alive()
    assert _port_closed(server.url)

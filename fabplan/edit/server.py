"""The local web server of `fabplan edit`: the page, its WebSocket, the scripting API.

Starlette on uvicorn, bound to 127.0.0.1 only. Every request needs the random token of
the URL the server prints (``?token=...`` or the header ``X-Fabplan-Token``); a request
whose ``Origin`` is not the server's own, or whose ``Host`` is not 127.0.0.1 or localhost
at its port, is refused (another web page the browser has open cannot drive it, nor can
a DNS rebinding). The session's commands run one at a time on a worker thread
(`fabplan.edit.command_queue.CommandQueue`), drags that wait being coalesced; solved states go
to every open page over its WebSocket, the latest only when a page is slow to take them.

The server ends on Ctrl-C, on ``POST /api/shutdown``, or a few seconds after the last
open page was closed (when a page was ever opened): the worker finishes its command,
the socket is closed, nothing is written that was not saved. The routes are described
in ``docs/edit.md``.
"""

from __future__ import annotations

import asyncio
import json
import secrets
import socket
import sys
import threading
import webbrowser
from concurrent.futures import Future
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..errors import FabplanError, InputError
from ..io.obj import format_obj
from ..net.mesh import QuadMesh
from ..net.validate import check_net, load_net
from .command_queue import CommandQueue
from .page import edit_page
from .session import EditOptions, EditSession

__all__ = ["EditServer", "run_editor", "require_web_stack", "LAST_PAGE_GRACE_SECONDS"]

HOST = "127.0.0.1"
#: after the last page closed, the server waits this long for one to come back (a reload)
LAST_PAGE_GRACE_SECONDS = 3.0


def require_web_stack() -> tuple[Any, Any]:
    """starlette and uvicorn, or an error that says how to install them."""
    try:
        import starlette  # noqa: F401
        import uvicorn
        import websockets  # noqa: F401
    except ImportError as exc:
        raise FabplanError(f"fabplan edit needs the web server packages ({exc.name} is missing): "
                           "pip install 'fabplan[edit]'") from None
    return starlette, uvicorn


class _Pages:
    """The open pages: each gets the latest state message, the ones in between dropped."""

    def __init__(self, on_empty: Callable[[], None]) -> None:
        self._latest: dict[int, tuple[asyncio.Event, list[str | None]]] = {}
        self._next = 0
        self.ever = False
        self._on_empty = on_empty
        self.loop: asyncio.AbstractEventLoop | None = None

    @property
    def count(self) -> int:
        return len(self._latest)

    def add(self) -> tuple[int, asyncio.Event, list[str | None]]:
        self._next += 1
        slot: tuple[asyncio.Event, list[str | None]] = (asyncio.Event(), [None])
        self._latest[self._next] = slot
        self.ever = True
        return self._next, slot[0], slot[1]

    def remove(self, key: int) -> None:
        self._latest.pop(key, None)
        if not self._latest and self.loop is not None:
            self.loop.call_later(LAST_PAGE_GRACE_SECONDS, self._check_empty)

    def _check_empty(self) -> None:
        if not self._latest:
            self._on_empty()

    def publish(self, text: str) -> None:
        """Hand a message to every page (call on the event loop)."""
        for event, box in self._latest.values():
            box[0] = text
            event.set()

    def publish_threadsafe(self, text: str) -> None:
        if self.loop is not None and not self.loop.is_closed():
            self.loop.call_soon_threadsafe(self.publish, text)


class EditServer:
    """A session served to browser pages and scripts.

    Parameters
    ----------
    session : the `EditSession` to serve.
    output : where Save writes the net (OBJ; its record beside it as ``.json``).
    port : the port on 127.0.0.1 (0: a free one).
    token : the token of the URL (default: a random one).

    Use `run` in a command (blocks until Ctrl-C, shutdown or the last page closed), or
    `start` and `stop` from Python (a notebook, a test): the server then runs on a thread.
    """

    def __init__(self, session: EditSession, output: str | Path | None = None, *,
                 port: int = 0, token: str | None = None) -> None:
        _, uvicorn = require_web_stack()
        self.session = session
        self.output = None if output is None else Path(output)
        self.token = token or secrets.token_urlsafe(24)
        self._socket = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._socket.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self._socket.bind((HOST, port))
        except OSError as exc:
            self._socket.close()
            raise InputError(f"--port {port}: cannot listen on {HOST}:{port} ({exc.strerror})") from None
        # listening from now on: a client given the address at once waits in the backlog
        self._socket.listen(64)
        self.port = int(self._socket.getsockname()[1])
        self.origins = {f"http://{HOST}:{self.port}", f"http://localhost:{self.port}"}
        self._hosts = {f"{HOST}:{self.port}", f"localhost:{self.port}"}
        self.queue = CommandQueue()
        self.pages = _Pages(self.stop)
        config = uvicorn.Config(self.app(), log_level="warning", ws="websockets-sansio",
                                lifespan="off", access_log=False, timeout_graceful_shutdown=3)
        self._server = uvicorn.Server(config)
        self._thread: threading.Thread | None = None
        self.stopped_by = ""

    @property
    def url(self) -> str:
        """The page's address, with the token."""
        return f"http://{HOST}:{self.port}/?token={self.token}"

    # ------------------------------------------------------------------ running
    def run(self) -> None:
        """Serve until stopped (Ctrl-C in the main thread, `stop`, the last page closed)."""
        try:
            self._server.run(sockets=[self._socket])
        finally:
            self.close()

    def start(self) -> EditServer:
        """Serve on a thread; returns when the server accepts connections."""
        self._thread = threading.Thread(target=self.run, name="fabplan-edit-server", daemon=True)
        self._thread.start()
        while not self._server.started:
            if not self._thread.is_alive():
                raise FabplanError("the edit server did not start")
            self._thread.join(0.02)
        return self

    def stop(self, why: str = "stopped") -> None:
        """Ask the server to end (it finishes the command running)."""
        self.stopped_by = self.stopped_by or why
        self._server.should_exit = True

    def join(self, timeout: float | None = None) -> None:
        if self._thread is not None:
            self._thread.join(timeout)

    def close(self) -> None:
        """End the worker and close the socket (after `run` returned)."""
        self.queue.close()
        self._socket.close()

    # ------------------------------------------------------------------ commands
    def _submit(self, command: Callable[[], Any], *, coalesce: str | None = None,
                publish: bool = True) -> Future:
        """Run a session command on the worker; after it, the new state goes to the pages."""
        def run() -> Any:
            value = command()
            if publish and self.pages.count:
                self.pages.publish_threadsafe(self._state_message())
            return value

        return self.queue.submit(run, coalesce=coalesce)

    def _state_message(self, *, scene: bool = True) -> str:
        """The state message the pages get: the session's state, the solved net's scene."""
        s = self.session
        message: dict[str, Any] = {"type": "state", **s.state(),
                                   "centre": s.centre.tolist(),
                                   "output": None if self.output is None else str(self.output)}
        if scene:
            message["scene"] = s.scene_json()
            message["normals"] = np.round(s.vertex_normals(), 6).ravel().tolist()
        return json.dumps(message, separators=(",", ":"))

    def _drag(self, targets: dict, gesture: str | None, positions: bool = True) -> dict:
        update = self.session.drag(targets, gesture=gesture)
        out = {**update.to_json(), "state": self.session.state()}
        if positions:     # taken here: the next command may move the net
            out["positions"] = self.session.vertices.tolist()
        return out

    def _save(self, path: str | None) -> dict:
        out = Path(path) if path else self.output
        if out is None:
            raise InputError("no output to save to: start fabplan edit with -o OUT.obj, or "
                             "give a path")
        if out.suffix.lower() != ".obj":
            raise InputError(f"{out}: the output must be an .obj file")
        obj, record = self.session.save(out)
        return {"saved": [str(obj), str(record)]}

    def _new_session(self, body: dict) -> dict:
        """Replace the session by the net of a request (see `docs/edit.md`)."""
        if "path" in body:
            mesh = load_net(str(body["path"]))
        else:
            try:
                mesh = QuadMesh(np.asarray(body["vertices"], dtype=np.float64),
                                [np.asarray(f, dtype=np.int64) for f in body["faces"]],
                                name=str(body.get("name", "posted net")))
            except (KeyError, TypeError, ValueError) as exc:
                raise InputError(f"the session needs 'vertices' (n x 3) and 'faces' (lists of "
                                 f"vertex ids) or a 'path' ({exc})") from None
            mesh = check_net(mesh)
        old = self.session.options
        known = {k: body[k] for k in ("net", "angle", "radius", "units", "tolerance",
                                      "max_iterations", "max_seconds", "influence") if k in body}
        options = EditOptions(**{**old.to_json(), "angle": None, "radius": None, **known})
        self.session = EditSession(mesh, options, handles=body.get("handles", ()),
                                   pins=body.get("pins", ()), source=str(body.get("path", mesh.name)))
        return self.session.state()

    # ------------------------------------------------------------------ the app
    def app(self) -> Any:
        from starlette.applications import Starlette
        from starlette.requests import Request
        from starlette.responses import HTMLResponse, JSONResponse, PlainTextResponse, Response
        from starlette.routing import Route, WebSocketRoute
        from starlette.websockets import WebSocket, WebSocketDisconnect

        def refused(scope_headers: Any, query: Any) -> str | None:
            host = scope_headers.get("host", "")
            if host not in self._hosts:
                return f"host {host!r} refused"
            origin = scope_headers.get("origin")
            if origin is not None and origin not in self.origins:
                return f"origin {origin!r} refused"
            given = query.get("token") or scope_headers.get("x-fabplan-token") or ""
            if not secrets.compare_digest(given.encode(), self.token.encode()):
                return "wrong or missing token"
            return None

        async def body_of(request: Request) -> dict:
            try:
                body = await request.json()
            except (json.JSONDecodeError, UnicodeDecodeError):
                raise InputError("the request body is not JSON") from None
            if not isinstance(body, dict):
                raise InputError("the request body must be a JSON object")
            return body

        async def answer(future: Future) -> Response:
            try:
                value = await asyncio.wrap_future(future)
            except (FabplanError, ValueError) as exc:
                return JSONResponse({"error": str(exc)}, status_code=400)
            return JSONResponse(value)

        def guarded(handler: Callable) -> Callable:
            async def endpoint(request: Request) -> Response:
                why = refused(request.headers, request.query_params)
                if why:
                    return PlainTextResponse(f"fabplan edit: {why}", status_code=403)
                try:
                    return await handler(request)
                except (FabplanError, ValueError) as exc:
                    return JSONResponse({"error": str(exc)}, status_code=400)
            return endpoint

        async def page(request: Request) -> Response:
            return HTMLResponse(edit_page(Path(self.session.source).name))

        async def session_post(request: Request) -> Response:
            body = await body_of(request)
            return await answer(self._submit(lambda: self._new_session(body)))

        async def drag(request: Request) -> Response:
            body = await body_of(request)
            try:
                ids = [int(i) for i in body["handles"]]
                points = np.asarray(body["targets"], dtype=np.float64).reshape(len(ids), 3)
            except (KeyError, TypeError, ValueError):
                raise InputError("a drag needs 'handles' (vertex ids) and 'targets' (one "
                                 "[x, y, z] per handle)") from None
            targets = dict(zip(ids, points, strict=True))
            gesture = body.get("gesture")
            positions = bool(body.get("positions", True))
            try:
                value = await asyncio.wrap_future(self._submit(
                    lambda: self._drag(targets, gesture, positions), coalesce="drag"))
            except (FabplanError, ValueError) as exc:
                return JSONResponse({"error": str(exc)}, status_code=400)
            # a drag replaced by a later one while it waited gets that one's result
            mine = {str(k): [float(c) for c in v] for k, v in targets.items()}
            return JSONResponse({**value, "coalesced": value["targets"] != mine})

        async def net(request: Request) -> Response:
            fmt = request.query_params.get("format", "json")

            def read() -> Any:
                s = self.session
                if fmt == "obj":
                    return format_obj(s.vertices, s.mesh.faces, f"fabplan edit: {s.source}")
                return {**s.state(), "positions": s.vertices.tolist(),
                        "faces": [f.tolist() for f in s.mesh.faces]}

            value = await asyncio.wrap_future(self._submit(read, publish=False))
            if fmt == "obj":
                return PlainTextResponse(value, media_type="model/obj")
            return JSONResponse(value)

        def simple(command: Callable[[dict], Any]) -> Callable:
            async def endpoint(request: Request) -> Response:
                body = await body_of(request) if await request.body() else {}
                return await answer(self._submit(lambda: command(body)))
            return endpoint

        def role(body: dict) -> dict:
            self.session.set_role(int(body["vertex"]), str(body.get("role", "handle")))
            return self.session.state()

        async def shutdown(request: Request) -> Response:
            self.stop("the shutdown request")
            return JSONResponse({"stopping": True})

        async def socket_endpoint(ws: WebSocket) -> None:
            why = refused(ws.headers, ws.query_params)
            if why:
                await ws.close(code=1008, reason=why)
                return
            await ws.accept()
            self.pages.loop = asyncio.get_running_loop()
            key, event, box = self.pages.add()

            async def send() -> None:
                while True:
                    await event.wait()
                    event.clear()
                    text, box[0] = box[0], None
                    if text is not None:
                        await ws.send_text(text)

            sender = asyncio.create_task(send())
            first = self.queue.submit(self._state_message)
            box[0] = await asyncio.wrap_future(first)
            event.set()
            try:
                while True:
                    message = await ws.receive_json()
                    self._from_page(message)
            except (WebSocketDisconnect, RuntimeError):
                pass
            finally:
                sender.cancel()
                self.pages.remove(key)

        routes = [
            Route("/", guarded(page)),
            Route("/favicon.ico", lambda request: Response(status_code=204)),
            Route("/api/session", guarded(session_post), methods=["POST"]),
            Route("/api/drag", guarded(drag), methods=["POST"]),
            Route("/api/net", guarded(net)),
            Route("/api/state", guarded(simple(lambda body: self.session.state())),
                  methods=["GET"]),
            Route("/api/role", guarded(simple(role)), methods=["POST"]),
            Route("/api/undo", guarded(simple(lambda body: self.session.undo())), methods=["POST"]),
            Route("/api/redo", guarded(simple(lambda body: self.session.redo())), methods=["POST"]),
            Route("/api/reset", guarded(simple(lambda body: self.session.reset())), methods=["POST"]),
            Route("/api/save", guarded(simple(lambda body: self._save(body.get("path")))),
                  methods=["POST"]),
            Route("/api/shutdown", guarded(shutdown), methods=["POST"]),
            WebSocketRoute("/ws", socket_endpoint),
        ]
        return Starlette(routes=routes)

    def _from_page(self, message: Any) -> None:
        """A command from a page (see `docs/edit.md`); its outcome reaches every page as
        the next state message, an error as an ``error`` message."""
        if not isinstance(message, dict):
            return
        kind = message.get("type")
        s = self.session
        commands: dict[str, Callable[[], Any]] = {
            "release": s.release,
            "undo": s.undo, "redo": s.redo, "reset": s.reset,
            "save": lambda: self._save(None),
        }
        if kind == "drag":
            targets = {int(k): v for k, v in dict(message.get("targets") or {}).items()}
            gesture = str(message.get("gesture", "page"))
            future = self._submit(lambda: s.drag(targets, gesture=gesture), coalesce="drag")
        elif kind == "role":
            future = self._submit(lambda: s.set_role(int(message["vertex"]), str(message["role"])))
        elif kind == "influence":
            def influence() -> None:
                s.options.influence = max(0.0, float(message["value"]))
            future = self._submit(influence)
        elif kind in commands:
            future = self._submit(commands[kind])
        else:
            return
        future.add_done_callback(self._report_error)

    def _report_error(self, future: Future) -> None:
        exc = future.exception()
        if exc is not None:
            self.pages.publish_threadsafe(json.dumps({"type": "error", "message": str(exc)}))


def run_editor(session: EditSession, output: str | Path, *, port: int = 0,
               open_browser: bool = True, quiet: bool = False) -> int:
    """Serve `session` until Ctrl-C, a shutdown request or the last page closed (the
    `fabplan edit` command). Returns the exit code (0)."""
    server = EditServer(session, output, port=port)
    try:
        print(f"fabplan edit: {server.url}", flush=True)
        if not quiet:
            print("fabplan edit: open the address above in a browser; Ctrl-C ends the server",
                  file=sys.stderr, flush=True)
        if open_browser:
            threading.Timer(0.3, webbrowser.open, args=(server.url,)).start()
        server.run()
    except KeyboardInterrupt:
        server.stopped_by = server.stopped_by or "Ctrl-C"
        server.close()
    if session is server.session and server.session.unsaved:
        print(f"fabplan edit: the last {server.session.changes - server.session.saved_changes} "
              f"changes were not saved to {output}", file=sys.stderr)
    elif server.session.unsaved:
        print("fabplan edit: the net posted to /api/session was not saved", file=sys.stderr)
    print(f"fabplan edit: ended ({server.stopped_by or 'Ctrl-C'})", file=sys.stderr, flush=True)
    return 0

"""Live editing of a net in the browser (`fabplan edit`): drag handles, the net follows.

A local web application: `server.EditServer` (Starlette on uvicorn, bound to 127.0.0.1,
a random token in its URL) serves the page (`page`) and a scripting interface over one
`session.EditSession`, whose commands run one at a time on a worker thread
(`command_queue.CommandQueue`: drags that wait are coalesced, the latest wins). The solves are
`fabplan.solve.edit.NetEditor.solve_drag`; a saved net carries its handles and edit
history in its record (`record`). The interface is described in ``docs/edit.md``.

May import: solve, net, report, io, errors (the stages below the command line: the
editor is a front end like `fabplan.cli`).
"""

from __future__ import annotations

__all__ = ["EditOptions", "EditSession", "EditServer", "run_editor"]


def __getattr__(name: str):
    # the web stack is an optional extra: imported when the editor is used
    if name in ("EditOptions", "EditSession"):
        from . import session

        return getattr(session, name)
    if name in ("EditServer", "run_editor"):
        from . import server

        return getattr(server, name)
    raise AttributeError(name)

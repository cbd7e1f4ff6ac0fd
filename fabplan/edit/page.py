"""The editing page: the reports' 3D view (`fabplan.report.viewer`) with the editing
tools of ``edit.js`` on top, in one HTML document served by `fabplan.edit.server`.

The page opens with an empty view; the server's first state message over the WebSocket
brings the net (a `fabplan.report.viewer.ViewerScene`), and every later one the solved
net after a command. The token of the page's address authenticates the WebSocket.
"""

from __future__ import annotations

import html
from importlib import resources

from ..report.viewer import viewer_assets

__all__ = ["edit_page", "EDIT_HELP"]

#: how to use the page, shown under the view
EDIT_HELP = ("Click a vertex to make it a handle (with the Pin tool: to hold it where it is; "
             "click again to free it). Drag a handle: it moves in the view plane, or along "
             "its normal with Shift held or 'along the normal' chosen. The net is solved "
             "while it moves; a drag the net cannot follow (not converged, folded, crumpled) "
             "leaves the last good net and marks where it fails in red. Drag elsewhere to "
             "orbit, scroll to zoom, right-drag to pan.")

_CSS = """
body { font-family: system-ui, sans-serif; margin: 0.6em 1em; color: #222; }
h1 { font-size: 1.15em; margin: 0.2em 0 0.4em; }
.fe-bar { display: flex; flex-wrap: wrap; gap: 0.5em; align-items: center; margin-bottom: 0.4em; }
.fe-bar button { border: 1px solid #aaa; background: #fff; padding: 0.2em 0.7em; cursor: pointer; }
.fe-bar button.fe-on { background: #dfe9f7; border-color: #4a7ab5; }
.fe-status { font-weight: 600; padding: 0.1em 0.5em; border-radius: 3px; }
.fe-converged { background: #d9f0d9; color: #1d5e1d; }
.fe-failed { background: #f8d7d7; color: #8a1c1c; }
.fe-message { color: #8a1c1c; min-height: 1.3em; font-size: 0.92em; }
.fe-numbers { font-variant-numeric: tabular-nums; color: #333; }
.note { color: #555; font-size: 0.9em; }
"""


def _script() -> str:
    return resources.files("fabplan.edit").joinpath("edit.js").read_text(encoding="utf-8")


def edit_page(title: str) -> str:
    """The page's HTML (its net arrives over the WebSocket)."""
    script = _script().replace("</script", "<\\/script")
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>fabplan edit: {html.escape(title)}</title>
<style>{_CSS}</style></head><body>
<h1>fabplan edit: {html.escape(title)}</h1>
<div class="fe-bar">
 <span>Tool</span>
 <button type="button" class="fe-tool fe-on" data-tool="handle">Handle</button>
 <button type="button" class="fe-tool" data-tool="pin">Pin</button>
 <span>Move</span>
 <button type="button" class="fe-move fe-on" data-move="plane">in the view plane</button>
 <button type="button" class="fe-move" data-move="normal">along the normal</button>
 <label>influence <input type="number" class="fe-influence" min="0" step="1" style="width:4em">
  edges</label>
 <button type="button" class="fe-undo">Undo</button>
 <button type="button" class="fe-redo">Redo</button>
 <button type="button" class="fe-reset">Reset</button>
 <button type="button" class="fe-save">Save</button>
</div>
<div class="fe-bar"><span class="fe-status">connecting</span>
 <span class="fe-numbers"></span></div>
<div class="fe-message"></div>
<div class="fp-viewer" id="fe-view">
<script type="application/json" class="fp-scenes">{{"scenes":[]}}</script></div>
<p class="note">{html.escape(EDIT_HELP)}</p>
{viewer_assets()}
<script>{script}</script>
</body></html>"""

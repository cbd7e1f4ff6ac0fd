"""The edit part of a saved net's record: handles, pins and history, and reading it back.

`fabplan edit` saves ``OUT.obj`` with ``OUT.json`` beside it: the record every optimized
net has (`docs/net-record.md`) and under ``edit`` what reopens the session where it was
left: the net type and options, the handles (vertex ids and where they are held), the
pinned vertices and the history of the edits.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import InputError

__all__ = ["EDIT_KEY", "SavedEdit", "edit_section", "read_saved"]

EDIT_KEY = "edit"
_OPTIONS = ("net", "angle", "radius", "units", "tolerance", "max_iterations", "max_seconds",
            "influence")


def edit_section(source: str | Path, options: dict, handles: dict, pins: Iterable[int],
                 history: list) -> dict:
    """The ``edit`` part of the record of an edit session's current net.

    Parameters
    ----------
    source : the net the session opened.
    options : the session's options as JSON (`EditOptions.to_json`).
    handles : vertex id -> (3,) float, where each handle holds its vertex.
    pins : ids of the pinned vertices.
    history : the session's edits, oldest first.
    """
    return {
        "source": str(source),
        "options": options,
        "handles": [{"vertex": k, "position": v.tolist()} for k, v in sorted(handles.items())],
        "pins": sorted(pins),
        "history": history,
    }


@dataclass
class SavedEdit:
    """What a saved net's record says about its editing (see the module)."""

    options: dict = field(default_factory=dict)
    handles: list[int] = field(default_factory=list)
    pins: list[int] = field(default_factory=list)
    history: list = field(default_factory=list)


def read_saved(net_path: str | Path) -> SavedEdit | None:
    """The edit part of the record beside a net (``NET.json``), or None when there is no
    such record or it has no edit part.

    Raises
    ------
    InputError
        When the record's edit part is malformed (named by its key).
    """
    path = Path(net_path).with_suffix(".json")
    if not path.is_file():
        return None
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None           # a record fabplan did not write: the net opens plainly
    edit: Any = record.get(EDIT_KEY) if isinstance(record, dict) else None
    if edit is None:
        return None
    try:
        options = {k: v for k, v in dict(edit.get("options") or {}).items() if k in _OPTIONS}
        handles = [int(h["vertex"]) for h in edit.get("handles") or []]
        pins = [int(p) for p in edit.get("pins") or []]
        history = list(edit.get("history") or [])
    except (TypeError, KeyError, ValueError, AttributeError):
        raise InputError(f"{path}: the '{EDIT_KEY}' part of the record is malformed "
                         "(handles need a vertex id, pins are vertex ids)") from None
    return SavedEdit(options, handles, pins, history)

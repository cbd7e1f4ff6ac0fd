"""JSON records: numpy values as plain JSON, undefined measurements as null."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np

from .output import write_texts

__all__ = ["json_text", "write_json"]


def _json_default(obj: object) -> object:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        return obj.item()
    raise TypeError(f"cannot serialise {type(obj).__name__}")


def _finite_or_none(obj: object) -> object:
    """Replace NaN and infinities (undefined measurements) by None, recursively."""
    if isinstance(obj, dict):
        return {k: _finite_or_none(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite_or_none(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _finite_or_none(obj.tolist())
    if isinstance(obj, (float, np.floating)) and not math.isfinite(obj):
        return None
    return obj


def json_text(record: dict) -> str:
    """JSON text of a record; numpy values become plain JSON, NaN and infinities null."""
    return json.dumps(_finite_or_none(record), indent=2, default=_json_default,
                      allow_nan=False) + "\n"


def write_json(path: str | os.PathLike, record: dict) -> None:
    """Write a JSON record atomically (see `json_text`)."""
    write_texts({Path(path): json_text(record)})

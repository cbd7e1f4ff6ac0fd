"""From a net to parts: one subpackage per product, and what the products share.

Owns, one room per product:
- `molds`: panels and molds (panel surfaces, materials and panel classes, the mold plan,
  boundary panels, the molds' report);
- `strips`: lamella strips (unrolling, the strips, parts on sheets, DXF sheets, the strip
  job with its files);
- `milling`: CNC milling paths (face and flank milling, the simulation of the cut, the
  report);
- `arcs`: circular arc structures (one module);
and what several products share: `limits`, the fabrication limits and their checks.
May import: `fabplan.layout`, `fabplan.design`, `fabplan.solve`, `fabplan.net`,
`fabplan.report`, `fabplan.io`, `fabplan.errors`. A product imports the shared modules of
this package, never another product (`molds`, `strips`, `milling` and `arcs` stay apart).
"""

import importlib
import sys
from typing import Any


def exported(package: str, exports: dict[str, str], name: str) -> Any:
    """The attribute `name` of the product room `package`, imported on first use from the
    module `exports` names for it and kept in the package (PEP 562: each room's module
    ``__getattr__`` calls this)."""
    if name not in exports:
        raise AttributeError(f"module {package!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(exports[name]), name)
    setattr(sys.modules[package], name, value)
    return value

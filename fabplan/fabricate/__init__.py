"""From a net to parts: panels and molds, lamella strips, nesting and DXF cutting files.

Owns: panel surfaces (`panels`), the mold plan (`molds`) and its report (`mold_report`),
lamella strips (`strips`), parts on sheets (`nesting`), DXF sheets (`dxf`) and the whole
strip job with its files (`strip_plan`), and circular arc structures (`arcs`).
May import: `fabplan.solve`, `fabplan.net`, `fabplan.report`, `fabplan.io`, `fabplan.errors`.
"""

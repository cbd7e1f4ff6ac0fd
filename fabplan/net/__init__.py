"""The net: a quad-dominant mesh and its discrete geometry.

Owns: `QuadMesh` and its combinatorics (`mesh`, `forest`, `index_rows`), discrete
geometry of stars (Meusnier and Mannheim spheres, normals, angles, principal curvatures:
`geometry`), the measurement of a net (`measure`), Weingarten fits of curvatures
(`weingarten`) and nets generated from formulas (`generate`).
May import: `fabplan.report`, `fabplan.io`, `fabplan.errors`.
"""

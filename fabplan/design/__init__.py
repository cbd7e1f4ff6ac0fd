"""Design surfaces: the shape a facade is planned on.

Owns: validated triangle meshes (`mesh_surface`), built-in parametric surfaces with exact
derivatives (`parametric`), exact NURBS surfaces read from Rhino files, trimmed or not
(`nurbs`), loading any of them from a file or a spec (`load`), and triangle mesh
topology (`topology`).
May import: `fabplan.solve`, `fabplan.net`, `fabplan.report`, `fabplan.io`, `fabplan.errors`.
"""

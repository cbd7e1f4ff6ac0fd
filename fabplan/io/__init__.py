"""Readers and writers, the checks every input passes, and the one output transaction.

Owns: OBJ quad meshes (`obj`), triangle mesh files (`triangles`), Rhino .3dm designs
in (`rhino_read`: surfaces, polysurface faces, meshes, units), JSON records
(`records`), atomic output files and folders (`output`), the checks of input files and
coordinates (`inputs`) and the memory guard of big runs (`resources`).
May import: `fabplan.errors` only.
"""

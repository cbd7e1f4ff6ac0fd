"""Readers and writers, the checks every input passes, and the one output transaction.

Owns: OBJ quad meshes (`obj`), triangle mesh files (`triangles`), Rhino .3dm designs
in (`rhino_read`: surfaces, polysurface faces, meshes, units), JSON records
(`records`), typed objects as JSON and arrays that read back without running code
(`typed_data`), atomic output files and folders (`output`), the checks of input files and
coordinates (`inputs`), the memory guard of big runs (`resources`), Rhino .3dm files of
nets and arcs (`rhino_write`) and binary glTF of nets (`gltf`).
May import: `fabplan.errors` only.
"""

"""Readers and writers, and the one output transaction.

Owns: OBJ quad meshes (`obj`), triangle mesh files (`triangles`), JSON records
(`records`), and atomic output files and folders (`output`).
May import: `fabplan.errors` only.
"""

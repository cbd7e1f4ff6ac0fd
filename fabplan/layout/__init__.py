"""From a design surface to an initial net (section 4.3 of the paper).

Owns: direction fields (`directions`), the global parametrization (`parametrization`),
quad extraction and boundary cells (`extraction`), one layout's lattice (`lattice`), the
pipeline and gliding solve (`surface_layout`), its starts (`starts`), settings
(`settings`) and picture (`picture`); the boundary panels: trimming (`trim`) in the
parameter plane (`parameter_chart`, `plane_cut`), the pieces on the surface
(`surface_pieces`), their outlines (`outlines`), coverage (`coverage`), soundness
(`soundness`, `off_design`, `overlaps`), gap patches (`gap_patches`) and the result
(`boundary_panels`).
May import: `fabplan.design`, `fabplan.solve`, `fabplan.net`, `fabplan.report`,
`fabplan.io`, `fabplan.errors`.
"""

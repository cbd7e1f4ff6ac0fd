"""From a design surface to an initial net (section 4.3 of the paper).

Owns: direction fields (`directions`), the global parametrization (`parametrization`),
quad extraction and boundary cells (`extraction`), the pipeline and gliding solve
(`surface_layout`), its settings (`settings`) and picture (`picture`).
May import: `fabplan.design`, `fabplan.solve`, `fabplan.net`, `fabplan.report`,
`fabplan.io`, `fabplan.errors`.
"""

"""The guided-projection solver (Algorithm 1 of the paper) and what it solves for.

Owns: the solver (`solver`), constraint families (`constraints`), sparse linear algebra
backends (`linalg`), the catalogue of net types (`net_types`), optimization presets
(`optimize`), handles (`edit`) and reference surfaces with exact closest points
(`reference`).
May import: `fabplan.net`, `fabplan.report`, `fabplan.io`, `fabplan.errors`.
"""

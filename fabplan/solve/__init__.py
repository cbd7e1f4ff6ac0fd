"""The guided-projection solver (Algorithm 1 of the paper) and what it solves for.

Owns: the solver (`solver`), constraint families (`constraints`), the normal equations'
sparsity pattern and its cache (`pattern`), sparse linear algebra backends (`linalg`), the
catalogue of net types (`net_types`), the whole solve of a net type (`optimize`, with the
solves it tries and how each ended, `attempts`; far targets reached in stages, `stages`;
held vertices and handles read from files, `handles`), live editing (`edit`), reference
surfaces with exact closest points
(`reference`), the smoothed start of a retry (`smoothing`) and the multilevel start of
large grid-patch nets (`multilevel`).
May import: `fabplan.net`, `fabplan.report`, `fabplan.io`, `fabplan.errors`.
"""

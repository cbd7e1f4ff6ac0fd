"""Facade feasibility studies: candidates laid out, solved, fabricated, judged and ranked.

Owns: the study file (`spec` reads it into the dataclasses of `definition`, each table
through `table`; `candidates` expands its candidates; `templates` are the bundled ones),
running the candidates (`run`: each one's `candidate_solve` and `candidate_measure`, its
molds counted in `mold_counts`, the nets it shares with an earlier one in `twins`),
judging them (`ranking`, with `verdict` and `checks`), running them on local processes or
a Dask cluster (`parallel`, with the inputs its tasks share: `inputs`) or measuring them
beside the run (`background`), the finished candidates kept for `--resume` (`cache`), the
files of a study (`report`: `records`, `pages` with their `tables`, `pictures`), and the
pipeline as plain calls for scripts (`api`: it wraps every stage below, so it lives at
the top of the flow).
May import: every stage below it (`fabplan.fabricate`, `.layout`, `.design`, `.solve`,
`.net`, `.report`, `.io`, `.errors`).
"""

"""Facade feasibility studies: candidates laid out, solved, fabricated, judged and ranked.

Owns: the study file (`spec`), running and judging the candidates (`run`), running them
on local processes or a Dask cluster (`parallel`, with the inputs its tasks share:
`inputs`), the finished candidates kept for `--resume` (`cache`), the files of a study
(`report`), and the pipeline as plain calls for scripts (`api`: it wraps every stage
below, so it lives at the top of the flow).
May import: every stage below it (`fabplan.fabricate`, `.layout`, `.design`, `.solve`,
`.net`, `.report`, `.io`, `.errors`).
"""

"""Facade feasibility studies: candidates laid out, solved, fabricated, judged and ranked.

Owns: the study file (`spec`), running and judging the candidates (`run`), and the files
of a study (`report`).
May import: every stage below it (`fabplan.fabricate`, `.layout`, `.design`, `.solve`,
`.net`, `.report`, `.io`, `.errors`).
"""

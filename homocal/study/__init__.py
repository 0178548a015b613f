"""The paper's evaluation (Sections 5-6): `homocal study DATASET... --out DIR`, then `homocal report DIR`.

perturb   trapezoid variants (hand-placed + seeded 0-3 px perturbations of 2..16 coordinates)
triples   every combination of three calibration points; sample counts
kernels   compiled second implementation of the correctors (regression, descent, hybrid, path errors)
inputs    the study's parameters (StudyParams) and a scene's calibration and test points (StudyScene)
shards    per-variant tables and the shard function shared by both engine paths, its identity and check
engine    results directory (study.json, variants, atomic shards), resume, in-process threads or Dask
cli       the `homocal study` subcommand
metrics, figures, report   the paper's Table 1, figures and the report page from a results directory
"""

"""The paper's evaluation (Sections 5-6): `homocal study DATASET... --out DIR`, then `homocal report DIR`.

perturb   trapezoid variants (hand-placed + seeded 0-3 px perturbations of 2..16 coordinates)
triples   every combination of three calibration points; sample counts
kernels   compiled second implementation of the correctors (regression, descent, hybrid, path errors)
scene     a scene's inputs, per-variant tables, and the shard function shared by both engine paths
engine    results directory (study.json, variants, atomic shards), resume, in-process threads or Dask
cli       the `homocal study` subcommand
metrics, figures, report   the paper's Table 1, figures and the report page from a results directory
"""

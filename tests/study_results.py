"""A hand-made study results directory after the contract (shards with the engine's metadata), shared by the
report tests (tests/study/test_study_report.py) and the output-folder tests (tests/homocal/test_outputs.py)."""
from __future__ import annotations

import itertools
import json
import random
import struct
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from homocal.study import metrics
from homocal.study.inputs import StudyParams
from homocal.study.shards import study_key

METHODS = metrics.METHODS
SCENES = {"alpha": (5.0, 9.0, 14.0, 20.0, 27.0, 35.0), "beta": (6.0, 11.0, 17.0, 24.0, 32.0)}  # calibration distances, m
VARIANTS = {"alpha": 3, "beta": 2}


def f32(x: float) -> float:
    """x rounded to float32 as the shards store it, in plain Python."""
    return struct.unpack("f", struct.pack("f", x))[0]


PARAMS = StudyParams(seed=3, n_variants=2, n_test=300)


def write_shard(root: Path, scene: str, variant: int, columns: dict[str, list], reason: str = "",
                params: StudyParams = PARAMS) -> None:
    """A shard file with the metadata the engine writes (scene.compute_shard) for the study of params."""
    types = {"variant": pa.int32(), "i": pa.int16(), "j": pa.int16(), "k": pa.int16(), "hybrid_regression": pa.bool_()}
    table = pa.table({c: pa.array(v, type=types.get(c, pa.float32())) for c, v in columns.items()})
    key = study_key(params.to_dict(), scene, "0" * 64)
    table = table.replace_schema_metadata({"degenerate_reason": reason, "scene": scene, "variant": str(variant),
                                           "study_key": key, "rows": str(table.num_rows)})
    pq.write_table(table, root / "shards" / scene / f"variant_{variant:05d}.parquet")


def write_results(root: Path, datasets: dict[str, str] | None = None, seed: int = 7, params: StudyParams = PARAMS) -> dict:
    """A results directory after the contract (the study of params, its values drawn with seed); returns
    {scene: {column: [values]}} of what the shards hold."""
    rng = random.Random(seed)
    stored = {}
    for scene, dist in SCENES.items():
        triples = list(itertools.combinations(range(len(dist)), 3))
        rows = {c: [] for c in ["variant", "i", "j", "k", "d_sum", "d_spread", "cal_before", "path_before", "hybrid_regression"]
                + [f"{kind}_{m}" for m in METHODS for kind in ("cal", "path")]}
        (root / "shards" / scene).mkdir(parents=True)
        for variant in range(VARIANTS[scene]):
            shard = {c: [] for c in rows}
            for i, j, k in triples:
                d = [dist[i], dist[j], dist[k]]
                shard["variant"].append(variant)
                for name, value in zip("ijk", (i, j, k)):
                    shard[name].append(value)
                shard["d_sum"].append(f32(sum(d)))
                shard["d_spread"].append(f32(max(d) - min(d)))
                shard["cal_before"].append(f32(rng.uniform(0.1, 2)))
                shard["path_before"].append(f32(rng.uniform(0.1, 2)))
                shard["hybrid_regression"].append(rng.random() < 0.7)
                for m in METHODS:
                    cal = 100 - rng.expovariate(1 / 15)
                    shard[f"cal_{m}"].append(f32(cal))
                    shard[f"path_{m}"].append(f32(0.8 * cal + rng.gauss(0, 30) - (200 if rng.random() < 0.03 else 0)))
            write_shard(root, scene, variant, shard, params=params)
            for c in rows:
                rows[c] += shard[c]
        if scene == "beta":  # its last variant is degenerate: an empty shard that says why
            write_shard(root, scene, 2, {c: [] for c in rows}, "collinear vertices", params=params)
        stored[scene] = rows
    (root / "shards" / "alpha" / "variant_00009.parquet.tmp").write_bytes(b"half-written")  # must be ignored
    n = sum(len(r["variant"]) for r in stored.values())
    study = {
        "format": "homocal-study", "preset": "test", **params.to_dict(),
        "datasets": [{"scene": s, "path": (datasets or {}).get(s, f"/nonexistent/{s}"), "config_hash": "0" * 64,
                      "n_calibration": len(SCENES[s])} for s in SCENES],
        "samples_total": n, "samples_done": n, "degenerate": [{"scene": "beta", "variant": 2, "reason": "collinear vertices"}],
        "complete": True, "elapsed": 1.5, "versions": {"homocal": "0.1.0"},
    }
    (root / "study.json").write_text(json.dumps(study))
    return stored

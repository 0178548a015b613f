"""Running a study into a results directory: variants, shards (one per trapezoid variant, each written
atomically), resume, and the same shard function in-process or on a Dask distributed cluster.

    DIR/study.json                                  parameters, datasets, counts, degenerate variants, complete
    DIR/timing.json                                 elapsed_seconds (wall time, summed over resumed runs)
    DIR/variants/<scene>.parquet                    every variant's offsets, n_perturbed, degenerate, reason
    DIR/shards/<scene>/variant_<00000>.parquet      one row per calibration triple (scene.SHARD_SCHEMA); its
                                                    schema metadata holds the variant's degenerate reason

Each variant's mapping is computed once, in its shard: the variants tables and the counts are written after
the shards, from the reasons the shards record (a killed run leaves them to the run that resumes it).
"""
from __future__ import annotations

import os
import platform
import time
from collections.abc import Iterator
from contextlib import contextmanager
from concurrent.futures import ALL_COMPLETED, FIRST_COMPLETED, ThreadPoolExecutor, wait
from importlib.metadata import version
from pathlib import Path

import numba
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from tqdm import tqdm

from homocal.files import output_folder, read_json, write_atomic, write_json_atomic
from homocal.study.perturb import draw_base_error
from homocal.study.inputs import StudyParams, StudyScene
from homocal.study.options import PRESETS
from homocal.study.shards import check_shard, compute_shard, study_key
from homocal.study.triples import n_samples

GROUP = 8  # variants per Dask task
FORMAT = "homocal-study"  # study.json's "format": marks a results directory as homocal study's (homocal.files.output_folder)


def shard_path(out: Path, scene: str, variant: int) -> Path:
    return out / "shards" / scene / f"variant_{variant:05d}.parquet"


def write_table(path: Path, table: pa.Table) -> None:
    """Parquet, atomically, without dictionary encoding (3x faster to write here, and smaller: the floats
    rarely repeat)."""
    write_atomic(path, lambda tmp: pq.write_table(table, tmp, use_dictionary=False))


def variants_table(scene: StudyScene, params: StudyParams, reasons: list[str]) -> pa.Table:
    """variants/<scene>.parquet: variant, horizon_shift_px (the base horizon's height above the true one, null
    without a horizon shift) and click_0..7 (the base error, px), img_0..7, map_0..7 (px offsets; the map ones
    in px of the dataset's site map, see StudyScene.variant_offsets), n_perturbed, degenerate, reason; reasons
    (n_variants + 1,) are the shards' ("" if not degenerate)."""
    n = params.n_variants + 1
    rows = [scene.variant_offsets(params, v) for v in range(n)]
    base = [draw_base_error(params.seed, scene.name, v, params.horizon_shift, params.click_noise) for v in range(n)]
    offsets, click = np.array([r[0] for r in rows]), np.array([b[1] for b in base])
    cols = {"variant": pa.array(np.arange(n, dtype=np.int32)),
            "horizon_shift_px": pa.array([b[0] for b in base], pa.float64())}  # null: the hand-placed trapezoid as it is
    cols |= {f"click_{c}": pa.array(click[:, c]) for c in range(8)}
    cols |= {f"img_{c}": pa.array(offsets[:, c]) for c in range(8)}
    cols |= {f"map_{c}": pa.array(offsets[:, 8 + c]) for c in range(8)}
    cols |= {"n_perturbed": pa.array(np.array([r[1] for r in rows], dtype=np.int8)),
             "degenerate": pa.array([bool(r) for r in reasons]), "reason": pa.array(reasons, pa.string())}
    return pa.table(cols)


def run_group(scene: StudyScene, params: StudyParams, variants: list[int]) -> list[tuple[int, pa.Table, str]]:
    """The unit of work of both engine paths: compute_shard for each variant of one loaded scene."""
    return [(v, *compute_shard(scene, params, v)) for v in variants]


def study_parameters(preset: str | None, params: StudyParams, scenes: list[StudyScene], paths: list[str]) -> dict:
    """The parameters part of study.json: what --resume compares (every StudyParams field, the datasets)."""
    return {
        "preset": preset, **params.to_dict(),
        "datasets": [{"scene": s.name, "path": str(Path(p).resolve()), "config_hash": s.config_hash,
                      "n_calibration": len(s.cal_image), "n_test": len(s.test_image)} for s, p in zip(scenes, paths)],
    }


def preset_label(preset: str | None) -> dict:
    """study.json's preset_label: what the preset is (options.PRESETS; e.g. "fitted to Table 1, not the paper's
    protocol"); nothing without a preset. Not compared by --resume."""
    return {} if preset is None else {"preset_label": PRESETS[preset].label}


def load_scenes(paths: list[str], params: StudyParams) -> list[StudyScene]:
    scenes = [StudyScene.from_dataset(str(Path(p).resolve()), params) for p in paths]  # read afresh: a dataset may be regenerated
    names = [s.name for s in scenes]
    if len(set(names)) != len(names):
        raise ValueError(f"two datasets have the same scene name: {names}")
    return scenes


def run_study(paths: list[str], out: str | Path, params: StudyParams, preset: str | None = None, resume: bool = False,
              workers: int | None = None, scheduler: str | None = None, progress: bool = True) -> dict:
    """Run (or resume) a study; returns the final study.json content plus elapsed_seconds (wall time of all the
    runs that wrote it, kept in timing.json so that study.json is the same bytes for the same inputs). Bad
    input raises ValueError before anything is written."""
    start = time.perf_counter()
    out = Path(out)
    scenes = load_scenes(paths, params)
    parameters = study_parameters(preset, params, scenes, paths)
    n_shards = len(scenes) * (params.n_variants + 1)
    with dask_client(workers, scheduler) as client, output_folder(out, FORMAT, resume, marker="study.json") as folder:
        study_file, timing_file = out / "study.json", out / "timing.json"
        if folder.resumed:
            previous = read_json(study_file)
            if {k: previous.get(k) for k in parameters} != parameters:
                raise ValueError(f"{out} holds a study with other parameters; --resume needs the same datasets and options")
        keys = {s.name: study_key(params.to_dict(), s.name, s.config_hash) for s in scenes}
        reasons = {(s.name, v): check_shard(shard_path(out, s.name, v), s.name, v, keys[s.name], len(s.triples))
                   for s in scenes for v in range(params.n_variants + 1) if shard_path(out, s.name, v).is_file()}
        shards = [shard_path(out, s.name, v).relative_to(out) for s in scenes for v in range(params.n_variants + 1)]
        folder.remove_temporaries(["study.json", "timing.json", *(f"variants/{s.name}.parquet" for s in scenes), *map(str, shards)])
        elapsed = read_json(timing_file).get("elapsed_seconds", 0.0) if timing_file.is_file() else 0.0
        study = {"format": FORMAT, **parameters, **preset_label(preset), "samples_total": sum(len(s.triples) * (params.n_variants + 1) for s in scenes),
                 "complete": False, "versions": versions()}
        write_json_atomic(study_file, study)  # after every refusal: a refused --resume leaves study.json as it was
        todo = [(s, v) for s in scenes for v in range(params.n_variants + 1) if (s.name, v) not in reasons]
        bar = tqdm(total=len(todo), unit="shard", desc="study", disable=not progress)
        with ThreadPoolExecutor(max_workers=1) as writer:  # writes overlap the next shard's computation
            writes = []
            for scene, variant, table, reason in _execute(todo, scenes, params, client):
                writes.append(writer.submit(write_table, shard_path(out, scene.name, variant), table))
                writes[-1].add_done_callback(lambda _: bar.update())
                reasons[scene.name, variant] = reason
            for w in writes:
                w.result()
        bar.close()
        for scene in scenes:
            write_table(out / "variants" / f"{scene.name}.parquet",
                        variants_table(scene, params, [reasons[scene.name, v] for v in range(params.n_variants + 1)]))
        study.update(_counts(scenes, reasons))
        study["complete"] = study["shards_done"] == n_shards
        write_json_atomic(study_file, study)
        elapsed += time.perf_counter() - start
        write_json_atomic(timing_file, {"elapsed_seconds": elapsed})
    return study | {"elapsed_seconds": elapsed}


@contextmanager
def dask_client(workers: int | None, scheduler: str | None) -> Iterator:
    """A Dask client of a local cluster of ``workers`` processes or of the running ``scheduler`` (None for neither:
    the study runs in-process); entered before the output folder is made, so a scheduler that cannot be reached
    leaves nothing behind."""
    if workers is None and scheduler is None:
        yield None
        return
    from dask.distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True) if scheduler is None else None
    try:
        client = Client(cluster if cluster is not None else scheduler)
    except BaseException as e:
        if cluster is not None:
            cluster.close()
        if isinstance(e, OSError) and scheduler is not None:
            raise ValueError(f"scheduler {scheduler!r}: cannot connect ({e})") from None
        raise
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _execute(todo, scenes, params, client):
    """Yield (scene, variant, table, reason) for every (scene, variant) of todo, in-process (client None) or on
    the Dask client's cluster (the loaded scenes are sent to the workers once each)."""
    groups = []
    for scene in scenes:
        vs = [v for s, v in todo if s is scene]
        groups += [(scene, vs[i:i + GROUP]) for i in range(0, len(vs), GROUP)]
    if client is None:  # one shard per thread at a time; the kernel releases the GIL
        with ThreadPoolExecutor(max_workers=os.cpu_count() or 1) as pool:
            window = 2 * (os.cpu_count() or 1)
            shards = [(s, [v]) for s, vs in groups for v in vs]
            futures = {}
            for n, (scene, vs) in enumerate(shards):
                futures[pool.submit(run_group, scene, params, vs)] = scene
                if len(futures) >= window or n == len(shards) - 1:
                    done, _ = wait(futures, return_when=FIRST_COMPLETED if n < len(shards) - 1 else ALL_COMPLETED)
                    for future in done:
                        for v, table, reason in future.result():
                            yield futures.pop(future), v, table, reason
        return
    from dask.distributed import as_completed

    remote = {s.name: client.scatter(s, broadcast=True) for s in scenes}
    futures = {client.submit(run_group, remote[s.name], params, vs, pure=False): s for s, vs in groups}
    for future in as_completed(futures):
        for v, table, reason in future.result():
            yield futures[future], v, table, reason


def _counts(scenes: list[StudyScene], reasons: dict[tuple[str, int], str]) -> dict:
    """samples_done, samples_degenerate, shards_done and the degenerate variants list, from the shards'
    degenerate reasons {(scene, variant): reason}."""
    per = {s.name: len(s.triples) for s in scenes}
    degenerate = [{"scene": s.name, "variant": v, "reason": r}
                  for s in scenes for (name, v), r in sorted(reasons.items()) if name == s.name and r]
    n_degenerate_samples = sum(per[d["scene"]] for d in degenerate)
    return {"samples_done": sum(per[name] for name, _ in reasons) - n_degenerate_samples,
            "samples_degenerate": n_degenerate_samples, "shards_done": len(reasons), "degenerate": degenerate,
            "n_degenerate": len(degenerate)}


def dry_run_counts(paths: list[str], params: StudyParams) -> list[dict]:
    """Per scene: its name (scene), samples ((n_variants + 1) x C(M, 3)), n_calibration (M) and n_test (the test
    points the study would use), as in study.json's datasets list."""
    return [{"scene": s.name, "samples": n_samples(len(s.cal_image), params.n_variants),
             "n_calibration": len(s.cal_image), "n_test": len(s.test_image)} for s in load_scenes(paths, params)]


def versions() -> dict:
    return {"python": platform.python_version(), "numpy": np.__version__, "numba": numba.__version__,
            "pyarrow": pa.__version__, "homocal": version("homocal")}

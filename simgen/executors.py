"""Where a run's chunks are rendered besides the run's own process: spawned processes or a Dask cluster.
Each gets contiguous blocks of chunks (``render_chunks``); the run follows the parts as they land."""
from __future__ import annotations

import os
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from typing import TYPE_CHECKING

from tqdm import tqdm

from simgen.chunks import DatasetError, build_id, render_chunks

if TYPE_CHECKING:
    from simgen.dataset import Run


def _blocks(chunks: list[int], n: int) -> list[list[int]]:
    """``chunks`` cut into at most n contiguous blocks of nearly equal length."""
    n = min(n, len(chunks))
    return [chunks[len(chunks) * i // n : len(chunks) * (i + 1) // n] for i in range(n)]


class _ParentWatch:
    """A worker's ``tick``: exit when the process that started it is gone (a killed run leaves no writer)."""

    def __init__(self) -> None:
        self.parent = os.getpid()

    def __call__(self, frames: int) -> None:
        if os.getppid() != self.parent:
            os._exit(1)


def _follow(run: Run, todo: list[int], futures: list, bar: tqdm) -> None:
    """Wait for the futures (concurrent or Dask), moving the bar and manifest.json as chunks land; the first
    failure cancels the rest and is raised."""
    shown = 0
    try:
        while True:
            frames = run.frames([c for c in todo if run.done(c)])
            bar.update(frames - shown)
            shown = frames
            failed = next((f for f in futures if f.done() and f.exception() is not None), None)
            if failed is not None:
                failed.result()
            run.record()
            if all(f.done() for f in futures):
                return
            time.sleep(0.5)
    finally:
        for f in futures:
            f.cancel()


def render_in_processes(run: Run, todo: list[int], workers: int, bar: tqdm) -> None:
    """Blocks of chunks in ``workers`` spawned processes, LP_NUM_THREADS = cores // workers (at least 1) each."""
    threads = max(1, (os.cpu_count() or 1) // workers)
    with ProcessPoolExecutor(workers, mp_context=get_context("spawn")) as pool:
        futures = [pool.submit(render_chunks, run.scene, run.seed, run.out, block, threads, _ParentWatch(),
                               expect=build_id())
                   for block in _blocks(todo, workers)]
        _follow(run, todo, futures, bar)


def dask_client(address: str):
    """A Dask client of the scheduler at ``address``; DatasetError (one line) if it cannot connect."""
    from distributed import Client  # noqa: PLC0415  (optional: only --scheduler needs it)

    try:
        return Client(address, timeout="10s")
    except (OSError, ValueError) as e:
        raise DatasetError(f"--scheduler {address}: cannot connect ({str(e).splitlines()[0]})") from None


def render_on_dask(run: Run, todo: list[int], client, bar: tqdm) -> None:
    """One block of chunks per worker of the Dask cluster (another worker takes it over if that one is lost);
    each worker's LP_NUM_THREADS is its host's cores over the workers on that host (at least 1). Workers
    should run one thread each (``dask worker ADDRESS --nthreads 1``)."""
    workers = sorted(client.scheduler_info()["workers"].items())
    cores, hosts = client.run(os.cpu_count), Counter(info["host"] for _, info in workers)
    futures = [client.submit(render_chunks, run.scene, run.seed, str(run.out), block,
                             max(1, cores[address] // hosts[info["host"]]), expect=build_id(), workers=[address],
                             allow_other_workers=True, pure=False)
               for (address, info), block in zip(workers, _blocks(todo, len(workers)))]  # fmt: skip
    _follow(run, todo, futures, bar)

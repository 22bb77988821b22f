"""Episodes over held-out seeds in parallel worker processes, with a progress bar."""

from __future__ import annotations

import math
import multiprocessing as mp
from collections.abc import Callable
from typing import Any


def run_seed_chunks(
    worker: Callable[[Any], list[Any]],
    job: Callable[[list[int]], Any],
    seeds: list[int],
    workers: int,
    max_chunk: int,
    desc: str,
    progress: bool,
) -> list[Any]:
    """``worker(job(chunk))`` over chunks of ``seeds``, in ``workers`` spawned processes.

    ``worker`` must be a top-level function (it is pickled) that returns one result per seed
    of its chunk; results come back in seed order.  Chunks of at most ``max_chunk`` seeds keep
    every process busy to the end and the progress bar moving.
    """
    size = max(1, min(max_chunk, math.ceil(len(seeds) / max(workers, 1))))
    jobs = [job(seeds[i : i + size]) for i in range(0, len(seeds), size)]
    pool = mp.get_context("spawn").Pool(workers) if workers > 1 else None
    chunks = pool.imap(worker, jobs) if pool is not None else map(worker, jobs)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(seeds), desc=desc, unit="ep")
    results: list[Any] = []
    try:
        for chunk in chunks:
            results.extend(chunk)
            if bar is not None:
                bar.update(len(chunk))
    finally:
        if bar is not None:
            bar.close()
        if pool is not None:
            pool.close()
            pool.join()
    return results

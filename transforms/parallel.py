"""Blocks of numpy work spread over a few threads.

NumPy releases the GIL inside its loops, so independent blocks of some thirty thousand rows
run in parallel on separate cores. ``threads=1`` runs everything inline, in order.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

from .arrays import blocks

T = TypeVar("T")


def map_blocks(work: Callable[[slice], T], n: int, threads: int = 1) -> list[T]:
    """``[work(block) for block in blocks(n)]``, on up to ``threads`` threads.

    ``work`` must only write to its own block of any shared output.
    """
    return run_all([lambda block=block: work(block) for block in blocks(n)], threads)


def run_all(tasks: Iterable[Callable[[], T]], threads: int = 1) -> list[T]:
    """Call every task and return their results in order, on up to ``threads`` threads.

    The first exception a task raises is raised here.
    """
    tasks = list(tasks)
    if threads <= 1 or len(tasks) <= 1:
        return [task() for task in tasks]
    with ThreadPoolExecutor(max_workers=min(threads, len(tasks))) as pool:
        futures = [pool.submit(task) for task in tasks]
        return [future.result() for future in futures]

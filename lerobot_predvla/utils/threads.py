"""Torch intra-op threads while a policy of the plugin acts on the CPU.

Acting runs many small matmuls and elementwise ops per control step (batch 1-10, widths of a few hundred). With
more than one thread, every one of them is a parallel region that waits for its slowest thread; on cores that
other work also uses, that wait is a scheduler time slice, and a control step takes several times longer than on one
thread (`benchmarks/bench_acting_threads.py`). So the front end and the policy's `select_action` run on one thread
on the CPU, and put torch's setting back afterwards. Setting `OMP_NUM_THREADS` chooses the count instead.
"""

import os
from collections.abc import Iterator
from contextlib import contextmanager

import torch

ACTING_THREADS = 1


def acting_threads_count() -> int | None:
    """Threads acting on the CPU uses: `ACTING_THREADS`, or None (torch's own setting) when OMP_NUM_THREADS is set."""
    return None if os.environ.get("OMP_NUM_THREADS") else ACTING_THREADS


@contextmanager
def torch_threads(threads: int | None) -> Iterator[None]:
    """Run the block on `threads` torch intra-op threads (None: torch's own setting); restore torch's setting."""
    before = torch.get_num_threads()
    if threads is None or before == threads:
        yield
        return
    torch.set_num_threads(threads)
    try:
        yield
    finally:
        torch.set_num_threads(before)


@contextmanager
def acting_threads(device: torch.device | str) -> Iterator[None]:
    """Run the block on `acting_threads_count()` torch threads if `device` is the CPU; restore torch's setting."""
    with torch_threads(acting_threads_count() if torch.device(device).type == "cpu" else None):
        yield

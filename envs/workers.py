"""One CPU per vector-env worker: why and how handsim pins Gymnasium's worker processes.

``gymnasium.vector.AsyncVectorEnv`` steps each env in a worker process that wakes when the
parent writes the action to its pipe. Linux tends to start a task woken that way on the waker's
CPU; measured on a 2-core machine, two handsim workers then often ran on one CPU for whole runs
(2 workers: 195 steps/s, no faster than 1 worker's 190), and 10 % of vector steps took twice the
time of a single worker's step even in good runs. Pinned, one worker per CPU, the same runs gave
350 to 369 steps/s, 1.85 to 1.93 times one worker.

So a handsim env created in a Gymnasium vector worker (process name ``Worker<...>-i``) pins its
process to the ``i``-th CPU it may run on (modulo their number). Nothing is pinned in any other
process, with only one CPU allowed, or when ``HANDSIM_PIN_WORKERS=0``. Turn it off when several
vector envs share the machine (each would pin its worker 0 to the same CPU), or when you place
workers on CPUs yourself.
"""

from __future__ import annotations

import multiprocessing
import os
import re

PIN_ENV_VAR = "HANDSIM_PIN_WORKERS"
"""Environment variable: ``0`` keeps Gymnasium's vector workers unpinned."""

_WORKER_NAME = re.compile(r"Worker<[^>]*>-(\d+)")
_pinned_cpu: dict[int, int | None] = {}  # process id -> CPU chosen there (once per process)


def pin_vector_worker() -> int | None:
    """Pin this process to one CPU if it is a Gymnasium vector-env worker (module docstring).

    Returns:
        The CPU this process is pinned to, or ``None`` when it was left alone. Repeated calls in
        one process return the first call's answer and change nothing.
    """
    pid = os.getpid()
    if pid in _pinned_cpu:
        return _pinned_cpu[pid]
    cpu = None
    match = _WORKER_NAME.fullmatch(multiprocessing.current_process().name)
    if (
        match is not None
        and os.environ.get(PIN_ENV_VAR, "1") != "0"
        and hasattr(os, "sched_setaffinity")
    ):
        allowed = sorted(os.sched_getaffinity(0))
        if len(allowed) > 1:
            cpu = allowed[int(match.group(1)) % len(allowed)]
            os.sched_setaffinity(0, {cpu})
    _pinned_cpu[pid] = cpu
    return cpu

"""Run independent tasks in worker processes, and keep control of them.

What ``concurrent.futures.ProcessPoolExecutor`` alone does not give a batch tool:

- **Ctrl-C (or SIGTERM) stops within a second**: no queue of thousands of submitted
  tasks is worked through; the workers are terminated and :class:`Interrupted` carries
  the results finished so far, so the caller can print its summary.
- **A dying worker costs only its task**: when a worker dies (out-of-memory kill, a
  crash in native code), the tasks that were running are retried one at a time in a
  fresh worker; a task that kills its worker again is reported as failed, not retried
  for ever; the other tasks go on.
- **No orphans**: workers ignore SIGINT (the parent decides) and, on Linux, are killed
  by the kernel when the parent dies, even by SIGKILL.
"""

from __future__ import annotations

import collections
import ctypes
import os
import signal
import sys
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any

__all__ = ["Interrupted", "run_in_workers"]

#: tasks submitted ahead per worker: enough to keep them busy, few enough to stop fast
_AHEAD = 2
#: how often the parent wakes up to notice Ctrl-C, seconds
_TICK = 0.2


class Interrupted(Exception):
    """The run was stopped (Ctrl-C, SIGTERM); ``done`` maps task index -> result."""

    def __init__(self, done: dict[int, Any]) -> None:
        super().__init__(f"interrupted after {len(done)} task(s)")
        self.done = done


def _worker_init(parent: int, n_workers: int = 1) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C
    # the workers share the CPUs: each runs its share of threads in a chunked runner
    # (tobitkf.smoothing.chunks), unless the person set TOBITKF_THREADS
    if not os.environ.get("TOBITKF_THREADS", "").strip():
        from tobitkf.smoothing.chunks import threads

        os.environ["TOBITKF_THREADS"] = str(max(1, threads() // max(1, n_workers)))
    # a handler inherited from the parent (the CLI turns SIGTERM into KeyboardInterrupt)
    # would not end a worker blocked waiting for work: SIGTERM ends a worker
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if sys.platform.startswith("linux"):
        try:  # die with the parent, whatever kills it (PR_SET_PDEATHSIG = 1)
            ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM), 0, 0, 0)
        except (OSError, AttributeError):  # pragma: no cover - not glibc
            pass
    if os.getppid() != parent:  # the parent died before the line above
        os._exit(1)


def _kill(pool: ProcessPoolExecutor) -> None:
    for proc in list(getattr(pool, "_processes", {}).values()):
        proc.terminate()
    pool.shutdown(wait=False, cancel_futures=True)


def run_in_workers(
    fn: Callable[[Any], Any],
    tasks: Sequence[Any],
    n_workers: int,
    *,
    on_result: Callable[[int, Any], None] | None = None,
    on_worker_death: Callable[[int], Any],
) -> dict[int, Any]:
    """``fn(task)`` for every task in ``n_workers`` processes; returns index -> result.

    ``fn`` must not raise (return a failure record instead): an exception is a bug and
    propagates. ``on_worker_death(index)`` makes the result of a task whose worker died
    twice. ``on_result(index, result)`` is called in the parent as results arrive.
    Raises :class:`Interrupted` on Ctrl-C / KeyboardInterrupt.
    """
    results: dict[int, Any] = {}
    pending = collections.deque(range(len(tasks)))
    suspects: collections.deque[int] = collections.deque()

    def record(i: int, value: Any) -> None:
        results[i] = value
        if on_result is not None:
            on_result(i, value)

    try:
        while pending or suspects:
            if suspects:  # one at a time, alone in a fresh worker
                i = suspects.popleft()
                with ProcessPoolExecutor(
                    1, initializer=_worker_init, initargs=(os.getpid(),)
                ) as pool:
                    fut = pool.submit(fn, tasks[i])
                    try:
                        value = _result(fut)
                    except BrokenProcessPool:
                        value = on_worker_death(i)
                record(i, value)
                continue
            broken = _run_batch(fn, tasks, n_workers, pending, record)
            suspects.extend(broken)
    except KeyboardInterrupt:
        raise Interrupted(results) from None
    return results


def _result(fut: Future) -> Any:
    while True:  # wake up regularly so that Ctrl-C is noticed
        done, _ = wait([fut], timeout=_TICK)
        if done:
            return fut.result()


def _run_batch(
    fn: Callable[[Any], Any],
    tasks: Sequence[Any],
    n_workers: int,
    pending: collections.deque[int],
    record: Callable[[int, Any], None],
) -> list[int]:
    """Run pending tasks in one pool until done or a worker dies; returns the tasks that
    were running when it died (to be retried one by one)."""
    pool = ProcessPoolExecutor(
        n_workers, initializer=_worker_init, initargs=(os.getpid(), n_workers)
    )
    inflight: dict[Future, int] = {}
    try:
        while pending or inflight:
            while pending and len(inflight) < _AHEAD * n_workers:
                i = pending.popleft()
                inflight[pool.submit(fn, tasks[i])] = i
            done, _ = wait(inflight, timeout=_TICK, return_when=FIRST_COMPLETED)
            for fut in done:
                i = inflight.pop(fut)
                try:
                    value = fut.result()
                except BrokenProcessPool:
                    # every task still in flight is suspect; queued ones go back
                    broken = [i, *inflight.values()]
                    _kill(pool)
                    return sorted(broken)
                record(i, value)
    except BaseException:
        _kill(pool)
        raise
    pool.shutdown(wait=True)
    return []

"""Run the per-file work of ``tobitkf smooth`` as tasks on a Dask cluster.

The engine is ``dask.distributed`` (the ``dask`` extra), not a scheduler of ours. Each
task is a group of files (small files are grouped so that the scheduling overhead stays
small against the work); the worker that runs it reads the inputs and writes the outputs
itself, atomically (:func:`~tobitkf.app.batch.run_task`, the same function as the local
pool), so inputs and outputs must be on storage every worker and the client see at the
same paths. Only per-file summaries travel back to the client.

A worker that dies (out of memory, a crash in native code, a lost node) costs only its
task: the scheduler reschedules the task (or, once its ``allowed-failures`` are spent,
reports ``KilledWorker``); each file of a killed task is then retried alone, one retry
at a time, and a file that was in a killed task twice is reported as failed, not retried
for ever. One at a time, because the scheduler fails every task assigned to a dead
worker, also those queued behind the one that killed it: two retries in flight could
meet on a worker again, and a good file would be failed with the bad one. ``--cluster
local`` starts a :class:`distributed.LocalCluster` with ``allowed-failures`` 0, so that a
file that kills two workers is failed after exactly those two deaths.
"""

from __future__ import annotations

import itertools
import logging
import os
import uuid
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any

from tobitkf.app.batch import FileSummary, Job, run_task

__all__ = ["INSTALL_HINT", "connect", "files_per_task", "import_distributed", "run_on_cluster"]

INSTALL_HINT = (
    "running on a Dask cluster needs dask.distributed, which is not installed: "
    "pip install 'tobitkf[dask]'"
)
#: files per task at most (a task then takes seconds, against milliseconds of overhead)
MAX_FILES_PER_TASK = 50
#: tasks per worker thread at least, so that the last ones do not leave workers idle
TASKS_PER_THREAD = 8
#: times a file may be in a task whose worker died before it is reported as failed
MAX_DEATHS = 2


def import_distributed() -> Any:
    """The ``distributed`` module, or ImportError saying how to install it."""
    try:
        import distributed
    except ImportError as exc:
        raise ImportError(INSTALL_HINT) from exc
    return distributed


@contextmanager
def connect(address: str, workers: int | None = None) -> Iterator[Any]:
    """A :class:`distributed.Client` for the run.

    ``address``: a scheduler address (``tcp://host:8786``), a scheduler file (a path
    ending in ``.json``, as written by ``dask scheduler --scheduler-file``), or
    ``"local"``: a :class:`~distributed.LocalCluster` of ``workers`` single-threaded
    worker processes (default: one per core) that lives as long as the context.
    """
    distributed = import_distributed()
    if address == "local":
        import dask

        config = {"distributed.scheduler.allowed-failures": 0}
        with dask.config.set(config):
            cluster = distributed.LocalCluster(
                n_workers=workers or os.cpu_count() or 1,
                threads_per_worker=1,
                processes=True,
                dashboard_address=":0",  # any free port (no clash with a running one)
                silence_logs=logging.ERROR,
            )
        try:
            with distributed.Client(cluster, set_as_default=False) as client:
                yield client
        finally:
            cluster.close()
        return
    if workers is not None:
        raise ValueError("--workers goes with --cluster local (a running cluster has its own)")
    if address.endswith(".json") and not os.path.isfile(address):
        raise ValueError(f"scheduler file {address} not found")
    if address.endswith(".json"):
        with distributed.Client(scheduler_file=address, set_as_default=False) as client:
            yield client
        return
    with distributed.Client(address, set_as_default=False) as client:
        yield client


def files_per_task(n_files: int, n_threads: int) -> int:
    """Files per task: enough tasks for ``TASKS_PER_THREAD`` per worker thread, at most
    ``MAX_FILES_PER_TASK`` files each."""
    per = n_files // max(1, n_threads * TASKS_PER_THREAD)
    return max(1, min(MAX_FILES_PER_TASK, per))


def run_group(tasks: Sequence[tuple[Any, ...]]) -> list[FileSummary]:
    """A task: :func:`run_task` for each file, on a worker (never raises for a file)."""
    return [run_task(*t) for t in tasks]


def _died(job: Job, deaths: int) -> FileSummary:
    return FileSummary(
        str(job.source),
        None,
        False,
        f"the Dask worker died while it was reading or smoothing it, {deaths} times (out of "
        "memory, or a crash in native code); nothing was written",
        extra={"planned_output": str(job.output)},
    )


def run_on_cluster(
    client: Any,
    jobs: Sequence[Job],
    method: str,
    params: dict[str, Any],
    *,
    offline: bool = False,
    expect: Sequence[str | None] | None = None,
    per_task: int | None = None,
    on_result: Callable[[int, FileSummary], None] | None = None,
) -> dict[int, FileSummary]:
    """Every job as part of a task on ``client``'s cluster; returns job index -> summary.

    ``expect`` as for :func:`~tobitkf.app.batch.run_jobs`. ``on_result(index, summary)``
    is called on the client as files finish. Ctrl-C cancels what is left and raises
    :class:`~tobitkf.app.pool.Interrupted` with the summaries received so far.
    """
    distributed = import_distributed()
    from tobitkf.app.pool import Interrupted

    hashes = list(expect) if expect is not None else [None] * len(jobs)
    args = [(job, method, params, offline, h) for job, h in zip(jobs, hashes, strict=True)]
    if per_task is None:
        per_task = files_per_task(len(jobs), sum(client.nthreads().values()))
    token = uuid.uuid4().hex[:12]
    results: dict[int, FileSummary] = {}
    deaths: dict[int, int] = {}
    members: dict[Any, list[int]] = {}

    submitted = itertools.count()

    def submit(idx: list[int]) -> Any:
        # a key never used before: a retry under the key of its killed task would get
        # that task's error back from the scheduler, a death the file never had
        key = f"tobitkf-smooth-{token}-{idx[0]}-{next(submitted)}"
        fut = client.submit(run_group, [args[i] for i in idx], key=key, pure=False)
        members[fut] = idx
        return fut

    def record(i: int, summary: FileSummary) -> None:
        results[i] = summary
        if on_result is not None:
            on_result(i, summary)

    order = list(range(len(jobs)))
    futures = [submit(order[k : k + per_task]) for k in range(0, len(order), per_task)]
    pending = distributed.as_completed(futures, loop=client.loop)  # not the default client
    retries: list[int] = []  # files of killed tasks, each to run alone, one at a time
    retrying: Any = None  # the retry in flight
    try:
        for fut in pending:
            idx = members.pop(fut)
            if fut is retrying:
                retrying = None
            try:
                summaries = fut.result()
            except distributed.KilledWorker:
                summaries = []  # each file is failed, or queued for a retry alone
                for i in idx:
                    deaths[i] = deaths.get(i, 0) + 1
                    if deaths[i] >= MAX_DEATHS:
                        record(i, _died(jobs[i], deaths[i]))
                    else:  # alone this time: a file that kills workers costs only itself
                        retries.append(i)
            except Exception as exc:  # the task could not run (e.g. tobitkf missing there)
                summaries = [
                    FileSummary(str(jobs[i].source), None, False, f"{type(exc).__name__}: {exc}")
                    for i in idx
                ]
            finally:
                fut.release()
            for i, summary in zip(idx, summaries, strict=False):  # none if the worker died
                record(i, summary)
            if retrying is None and retries:
                retrying = submit([retries.pop(0)])
                pending.add(retrying)
    except KeyboardInterrupt:
        client.cancel(list(members))
        raise Interrupted(results) from None
    return results

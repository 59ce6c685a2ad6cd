"""The retry bookkeeping of `run_on_cluster`, against a stand-in for Dask's scheduler.

Two rules of the real scheduler matter and are what the stand-in does: a worker that
dies fails every task assigned to it (the one that killed it and those queued behind),
and a task submitted under a key the scheduler still holds is not run again, its held
result (an error) comes back. The order in which the client hears of the failed tasks
is the scheduler's; the stand-in gives the killer's companions first, the order in which
a retry once went out under its killed task's key (seen in a CI run of
tests/test_cluster.py, where a good file was failed after one death).
"""

from __future__ import annotations

from pathlib import Path

import pytest

distributed = pytest.importorskip(
    "distributed", reason="dask.distributed is not installed (pip install 'tobitkf[dask]')"
)

from tobitkf.app import cluster  # noqa: E402
from tobitkf.app.batch import FileSummary, Job  # noqa: E402

KILLER = "killer"


class _Future:
    def __init__(self, key: str, jobs: list[Job]) -> None:
        self.key, self.jobs = key, jobs
        self.error: BaseException | None = None

    def result(self) -> list[FileSummary]:
        if self.error is not None:
            raise self.error
        return [FileSummary(str(j.source), str(j.output), True) for j in self.jobs]

    def release(self) -> None:
        pass


class _Client:
    """One worker, one thread: tasks run in submission order."""

    loop = None

    def __init__(self) -> None:
        self.held: dict[str, _Future] = {}  # every key the scheduler has seen
        self.queue: list[_Future] = []
        self.keys: list[str] = []

    def nthreads(self) -> dict[str, int]:
        return {"tcp://worker": 1}

    def submit(self, fn, tasks, key, pure):
        self.keys.append(key)
        if key in self.held:  # the scheduler's held result, not a new run
            return self.held[key]
        fut = _Future(key, [t[0] for t in tasks])
        self.held[key] = fut
        self.queue.append(fut)
        return fut


class _AsCompleted:
    """The futures in the order the stand-in scheduler finishes them."""

    def __init__(self, client: _Client) -> None:
        self.client = client
        self.ready: list[_Future] = []

    def add(self, fut: _Future) -> None:
        if fut.error is not None:  # a held error comes back at once
            self.ready.append(fut)

    def __iter__(self):
        return self

    def __next__(self) -> _Future:
        if not self.ready:
            if not self.client.queue:
                raise StopIteration
            head = self.client.queue[0]
            if any(j.source.stem == KILLER for j in head.jobs):  # the worker dies
                victims, self.client.queue = self.client.queue, []
                for v in victims:
                    v.error = distributed.KilledWorker(v.key, "tcp://worker", 0)
                self.ready = victims[1:] + victims[:1]  # the companions first
            else:
                self.ready = [self.client.queue.pop(0)]
        return self.ready.pop(0)


def _jobs(names: list[str]) -> list[Job]:
    return [Job(Path(f"/in/{n}.skeleton"), Path(f"/out/{n}.skeleton"), "ntu") for n in names]


@pytest.mark.parametrize(
    "names",
    [
        [KILLER, "a", "b", "c"],  # good files queued behind the killer
        ["a", KILLER, "b"],
        ["a", "b", "c", KILLER],
        [KILLER, "a", KILLER, "b"],
    ],
)
def test_only_the_file_that_kills_is_failed_whatever_the_order(monkeypatch, names):
    client = _Client()
    monkeypatch.setattr(distributed, "as_completed", lambda futures, loop: _AsCompleted(client))
    jobs = _jobs(names)
    results = cluster.run_on_cluster(client, jobs, "robust", {}, per_task=1)
    assert sorted(results) == list(range(len(jobs)))  # every file has its summary
    failed = sorted(i for i, r in results.items() if not r.ok)
    assert failed == [i for i, n in enumerate(names) if n == KILLER]
    for i in failed:
        assert f"{cluster.MAX_DEATHS} times" in results[i].error
    assert len(set(client.keys)) == len(client.keys)  # no key submitted twice

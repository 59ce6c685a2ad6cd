"""Bounded working memory (tobitkf.smoothing.chunks): a batch smoothed a chunk of bodies
at a time gives exactly the numbers of the batch in one piece."""

from __future__ import annotations

import os
from typing import Any

import numpy as np
import pytest

import tobitkf as tk
from tobitkf.smoothing import baselines, chunks, robust
from tobitkf.smoothing.baselines import savgol

T, B = 150, 5


def _bodies(seed: int = 3) -> np.ndarray:
    """(T, B, 25, 3) Kinect-like bodies in metres: a random walk of a rigid skeleton, a
    noise level of its own per body (the pooled recording gates differ from any one
    body's), spikes and sustained failures (rejections), 3 % missing."""
    rng = np.random.default_rng(seed)
    J = 25
    offsets = rng.normal(scale=0.15, size=(1, B, J, 3))
    root = np.cumsum(rng.normal(scale=0.01, size=(T, B, 1, 3)), axis=0) + np.array([0, 0, 2.5])
    sd = np.array([0.002, 0.005, 0.01, 0.02, 0.004])[None, :, None, None]
    noise = rng.normal(size=(T, B, J, 3)) * sd
    y = root + offsets + noise
    spikes = rng.uniform(size=(T, B, J)) < 0.01
    y[spikes] += rng.normal(scale=0.4, size=(int(spikes.sum()), 3))
    y[40:60, 1, 11] += [0.5, -0.3, 0.2]  # a hand failing for 20 frames
    y[rng.uniform(size=(T, B, J)) < 0.03] = np.nan
    return y


def _metric() -> list[tk.SkeletonSequence]:
    y = _bodies()
    rng = np.random.default_rng(5)
    states = rng.choice([0, 1, 2], p=[0.02, 0.08, 0.9], size=y.shape[:-1]).astype(np.int8)
    return [
        tk.SkeletonSequence(positions=y[:, b], topology="kinect_v2", fps=30.0,
                            tracking_state=states[:, b])
        for b in range(B)
    ]  # fmt: skip


def _pixels() -> list[tk.SkeletonSequence]:
    """2-D, in pixels, with confidence (some below min_confidence): recording gates."""
    y = 300.0 + 400.0 * _bodies(seed=4)[..., :2]
    conf = np.random.default_rng(6).uniform(0.05, 1.0, size=y.shape[:-1])
    return [
        tk.SkeletonSequence(positions=y[:, b], topology="kinect_v2", fps=30.0, units="px",
                            confidence=conf[:, b])
        for b in range(B)
    ]  # fmt: skip


def _same(a: Any, b: Any, where: str = "") -> None:
    """a == b exactly: arrays bit for bit (NaN where NaN), dicts and lists item by item."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), where
        for k in a:
            _same(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, (list, tuple)):
        assert isinstance(b, (list, tuple)) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _same(x, y, f"{where}[{i}]")
    elif isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        assert a.dtype == b.dtype and a.shape == b.shape, where
        nan = a.dtype.kind == "f"
        assert np.array_equal(a, b, equal_nan=nan), f"{where}: differs"
    elif isinstance(a, float) and np.isnan(a):
        assert isinstance(b, float) and np.isnan(b), where
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


def _compare(one: list[tk.SkeletonSequence], chunked: list[tk.SkeletonSequence]) -> None:
    for b, (x, y) in enumerate(zip(one, chunked, strict=True)):
        for field in ("positions", "std", "sample_state", "tracking_state"):
            _same(getattr(x, field), getattr(y, field), f"body {b} {field}")
        _same(x.metadata["diagnostics"], y.metadata["diagnostics"], f"body {b} diagnostics")


def _count_calls(monkeypatch: pytest.MonkeyPatch, module: Any, name: str) -> list[int]:
    calls: list[int] = []
    original = getattr(module, name)

    def spy(*args: Any, **kwargs: Any) -> Any:
        calls.append(1)
        return original(*args, **kwargs)

    monkeypatch.setattr(module, name, spy)
    return calls


@pytest.mark.parametrize("method", ["robust", "robust_online", "savgol", "sgf"])
@pytest.mark.parametrize("data", [_metric, _pixels], ids=["metres", "pixels"])
def test_chunked_run_equals_one_piece(monkeypatch, method, data):
    seqs = data()
    one = tk.smooth(seqs, method=method)
    if method.startswith("robust"):
        diag = one[1].metadata["diagnostics"]
        assert diag["rejected"][40:60, 11].any()  # the data exercise the gates
        if method == "robust":
            assert "noise_fit" in diag
    # one body (savgol: one column) per chunk, then 2 + 3 bodies / 3 x 125 columns
    per_body = T * 25 * 3 * 8
    if method.startswith("robust"):
        calls, smallest = _count_calls(monkeypatch, robust, "_robust_chunk"), B
    else:
        calls, smallest = _count_calls(monkeypatch, baselines, "_savgol_columns"), B * 75
    monkeypatch.setenv("TOBITKF_THREADS", "1")  # the budget is a single chunk's
    for budget, n_chunks in ((1, smallest), (2 * per_body, 3)):
        monkeypatch.setattr(chunks, "CHUNK_BYTES", budget)
        calls.clear()
        _compare(one, tk.smooth(seqs, method=method))
        assert len(calls) == n_chunks  # it did run in chunks


def test_chunks_cut_evenly_within_the_budget(monkeypatch):
    monkeypatch.setattr(chunks, "CHUNK_BYTES", 20)
    assert chunks.chunks(7, 10) == [slice(0, 1), slice(1, 3), slice(3, 5), slice(5, 7)]
    assert chunks.chunks(4, 5) == [slice(0, 4)]
    assert chunks.chunks(3, 100) == [slice(0, 1), slice(1, 2), slice(2, 3)]  # one at least
    assert chunks.chunks(1, 0) == [slice(0, 1)]


def test_savgol_column_does_not_depend_on_its_neighbours():
    """The edge fit is per column: a column smoothed alone or among others gives the same
    bits, and the edges are the least-squares polynomial of the first / last window."""
    rng = np.random.default_rng(0)
    x = rng.normal(size=(60, 40)).cumsum(axis=0) + 100.0
    together = savgol(x, 9, 3)
    for c in (0, 17, 39):
        np.testing.assert_array_equal(savgol(x[:, c], 9, 3), together[:, c])
    u = np.arange(9.0)
    for c in (0, 17):
        head = np.polyval(np.polyfit(u, x[:9, c], 3), u[:4])
        tail = np.polyval(np.polyfit(u, x[-9:, c], 3), u[5:])
        np.testing.assert_allclose(together[:4, c], head, rtol=0, atol=1e-11)
        np.testing.assert_allclose(together[-4:, c], tail, rtol=0, atol=1e-11)


def _cpus() -> int:
    if hasattr(os, "sched_getaffinity"):  # Linux: the CPUs this process may use
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


@pytest.mark.parametrize("method", ["robust", "robust_online"])
def test_chunks_in_threads_give_the_numbers_of_one_thread(monkeypatch, method):
    import threading

    seqs = _metric()
    monkeypatch.setattr(chunks, "CHUNK_BYTES", 1)  # a body per chunk: five chunks
    monkeypatch.setenv("TOBITKF_THREADS", "1")
    one = tk.smooth(seqs, method=method)
    names: list[str] = []
    original = robust._robust_chunk

    def spy(*args: Any, **kwargs: Any) -> Any:
        names.append(threading.current_thread().name)
        return original(*args, **kwargs)

    monkeypatch.setattr(robust, "_robust_chunk", spy)
    monkeypatch.setenv("TOBITKF_THREADS", "3")
    _compare(one, tk.smooth(seqs, method=method))
    assert len(names) == B and all(n.startswith("tobitkf-chunk") for n in names)


def test_threads_come_from_the_environment_or_the_cpus(monkeypatch):
    monkeypatch.setenv("TOBITKF_THREADS", " 3 ")
    assert chunks.threads() == 3
    for bad in ("0", "-1", "two", "1.5"):
        monkeypatch.setenv("TOBITKF_THREADS", bad)
        with pytest.raises(ValueError, match="TOBITKF_THREADS"):
            chunks.threads()
    monkeypatch.delenv("TOBITKF_THREADS")
    assert chunks.threads() == _cpus()


def test_a_large_batch_is_spread_over_the_threads(monkeypatch):
    monkeypatch.setattr(chunks, "SPREAD_BYTES", 50)
    assert chunks.chunks(7, 10, spread=3) == [slice(0, 2), slice(2, 4), slice(4, 7)]
    assert chunks.chunks(2, 30, spread=3) == [slice(0, 1), slice(1, 2)]  # an item at least
    assert chunks.chunks(4, 10, spread=3) == [slice(0, 4)]  # 40 bytes: not worth threads
    assert chunks.chunks(7, 10) == [slice(0, 7)]
    monkeypatch.setattr(chunks, "CHUNK_BYTES", 40)  # two threads share it: 20 bytes each
    assert chunks.chunks(6, 10, spread=2) == [slice(0, 2), slice(2, 4), slice(4, 6)]


def test_worker_processes_share_the_cpus(monkeypatch):
    from tobitkf.app.pool import run_in_workers

    def died(i: int) -> str:
        raise AssertionError("a worker died")

    monkeypatch.delenv("TOBITKF_THREADS", raising=False)
    cpus = _cpus()
    got = run_in_workers(os.getenv, ["TOBITKF_THREADS"] * 2, 2, on_worker_death=died)
    assert set(got.values()) == {str(max(1, cpus // 2))}
    monkeypatch.setenv("TOBITKF_THREADS", "5")  # the person's choice is kept
    got = run_in_workers(os.getenv, ["TOBITKF_THREADS"], 2, on_worker_death=died)
    assert got == {0: "5"}


def test_a_failing_chunk_stops_the_others_and_raises():
    import time

    started: list[int] = []

    def fn(part: slice) -> int:
        started.append(part.start)
        if part.start == 0:
            raise RuntimeError("chunk 0 failed")
        time.sleep(0.05)
        return part.start

    parts = [slice(i, i + 1) for i in range(40)]
    with pytest.raises(RuntimeError, match="chunk 0 failed"):
        chunks.map_chunks(fn, parts, 2)
    assert len(started) < 10  # the queued chunks were cancelled, not all run
    assert chunks.map_chunks(lambda p: p.start, parts, 3) == list(range(40))  # in order

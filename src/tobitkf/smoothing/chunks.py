"""Bounded working memory: a large batch goes through a method a chunk at a time.

A runner that works body by body (or column by column) and allocates several arrays
of the input's size for its intermediate results would need many times the input
for a large batch (200 recordings x 3000 frames x 25 joints: 343 MiB of input, 2.9 GiB
for ``robust`` in one piece). Such a runner allocates its outputs once and fills them
a chunk of bodies at a time, each chunk holding about :data:`CHUNK_BYTES` of input,
so its working set is bounded whatever the batch size. Whatever the runner derives
from the whole batch (``robust``'s recording gates pool all bodies of a call) is
derived once, before the chunks: a chunked run gives exactly the numbers of a run in
one piece (tests/test_chunks.py).

The chunks are independent, so a runner whose kernels release the GIL runs them in
threads (:func:`map_chunks`): :func:`threads` of them, the CPUs this process may use
unless ``TOBITKF_THREADS`` says otherwise (``tobitkf smooth --jobs N`` gives each of its
N worker processes its share). The chunks in flight share the memory budget, and a
batch large enough to gain (:data:`SPREAD_BYTES`) is cut into at least as many chunks as
threads. The numbers do not depend on the threads.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

__all__ = ["CHUNK_BYTES", "SPREAD_BYTES", "chunks", "map_chunks", "threads"]

R = TypeVar("R")

#: bytes of input a chunk holds (a chunk has at least one item). 16 MiB: a 3000-frame
#: Kinect body is 1.7 MiB (9 per chunk), and 12 x 1500 frames, the speed benchmark's
#: batch (10 MiB), is one chunk; the kernels' time per call dwarfs the loop's.
CHUNK_BYTES = 16 * 2**20


#: a batch of at least this much input is cut into at least :func:`threads` chunks
#: (when it has that many items): below it, starting threads costs more than it gains
SPREAD_BYTES = 2**20


def threads() -> int:
    """Threads a chunked runner uses: ``TOBITKF_THREADS`` when set (a positive
    integer), else the CPUs this process may run on."""
    text = os.environ.get("TOBITKF_THREADS", "").strip()
    if text:
        try:
            n = int(text)
        except ValueError:
            n = 0
        if n < 1:
            raise ValueError(f"TOBITKF_THREADS must be a positive integer, found {text!r}")
        return n
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # not Linux
        return max(1, os.cpu_count() or 1)


def chunks(n: int, item_bytes: int, spread: int = 1) -> list[slice]:
    """``range(n)`` cut into consecutive slices of equal size (within one) holding at
    most :data:`CHUNK_BYTES` of ``item_bytes`` each (one item at least); one slice
    ``0:n`` when everything fits. ``spread`` > 1 (threads): the ``spread`` chunks in
    flight hold at most :data:`CHUNK_BYTES` together, and a batch of at least
    :data:`SPREAD_BYTES` is cut into at least ``min(n, spread)`` slices."""
    per = max(1, CHUNK_BYTES // max(1, spread) // max(1, item_bytes))
    count = max(1, -(-n // per))
    if spread > 1 and n * item_bytes >= SPREAD_BYTES:
        count = max(count, min(n, spread))
    return [slice(i * n // count, (i + 1) * n // count) for i in range(count)]


def map_chunks(fn: Callable[[slice], R], parts: Sequence[slice], n_threads: int) -> list[R]:
    """``[fn(p) for p in parts]``, in order, run in up to ``n_threads`` threads (``fn``
    must release the GIL for its heavy work and write only its own part)."""
    n = min(n_threads, len(parts))
    if n <= 1:
        return [fn(p) for p in parts]
    with ThreadPoolExecutor(n, thread_name_prefix="tobitkf-chunk") as pool:
        # a chunk that raises, or Ctrl-C, cancels the chunks not yet started (map's own
        # clean-up), so the error surfaces after the running ones, not after all
        return list(pool.map(fn, parts))

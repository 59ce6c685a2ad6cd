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
"""

from __future__ import annotations

__all__ = ["CHUNK_BYTES", "chunks"]

#: bytes of input a chunk holds (a chunk has at least one item). 16 MiB: a 3000-frame
#: Kinect body is 1.7 MiB (9 per chunk), and 12 x 1500 frames, the speed benchmark's
#: batch (10 MiB), is one chunk; the kernels' time per call dwarfs the loop's.
CHUNK_BYTES = 16 * 2**20


def chunks(n: int, item_bytes: int) -> list[slice]:
    """``range(n)`` cut into consecutive slices of equal size (within one) holding at
    most :data:`CHUNK_BYTES` of ``item_bytes`` each (one item at least); one slice
    ``0:n`` when everything fits."""
    per = max(1, CHUNK_BYTES // max(1, item_bytes))
    count = max(1, -(-n // per))
    return [slice(i * n // count, (i + 1) * n // count) for i in range(count)]

"""Compile the methods' kernels ahead of the work (``tobitkf warmup``).

The compiled methods (the robust pair, the Kalman-type ones, the Kinect and 1€ filters)
are numba kernels, and so are the output states :func:`~tobitkf.smoothing.api.smooth`
works out for every method (:mod:`tobitkf.smoothing.output_states`); all are cached on
disk (numba's cache: ``__pycache__`` beside the package, or ``NUMBA_CACHE_DIR``). The
first call on a new machine, or after an upgrade, compiles them: seconds for the Kalman
methods, from twenty seconds to a minute or two (by machine) for ``robust``, whose gates,
untangling and noise fit (its likelihood and optimiser) have kernels of their own
(``tobitkf warmup`` prints the seconds); every later process loads them from the cache in
a second or so.

:func:`warm` runs a method on a small built-in recording, on several people in pixels
(and, for causal methods with a live stepper, a few live frames of one person and of
several), so that its kernels are compiled and cached before the real work starts, and
says when something had to be compiled (``on_compile``).
``tobitkf smooth`` calls it before it reads the first file, so that parallel workers
(``--jobs``) load the kernels instead of each compiling them, and the person waiting
sees why the first run is slow. :func:`warmup` does it for many methods, in parallel
processes (``make install`` runs ``tobitkf warmup``).

The kernels' types do not depend on the recording (every array reaches them as C-ordered
float64, bool or int), so warming on the small recording covers real files; a kernel
compiled apart for data where nothing fails (the robust smoother without shared errors)
is warmed on a still, clean recording too.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from multiprocessing import get_context
from typing import Any

import numpy as np

from tobitkf.skeleton.sequence import SkeletonSequence, TrackingState
from tobitkf.skeleton.topology import get_topology

# importing api registers the built-in methods
from tobitkf.smoothing.api import (
    DEFAULT_LIVE_METHOD,
    DEFAULT_METHOD,
    get_method,
    method_names,
    smooth,
)

__all__ = ["tiny_recording", "warm", "warmup"]

#: frames of the built-in recording: long enough for every rule to run (gaps, rejections,
#: the noise fit), short enough to cost nothing once compiled
TINY_FRAMES = 90


def tiny_recording(clean: bool = False) -> SkeletonSequence:
    """A 3 s Kinect V2 recording at 30 fps with tracking states, gaps and a glitch
    (``clean``: a still body, all of it tracked, nothing rejected)."""
    topo = get_topology("kinect_v2")
    rng = np.random.default_rng(0)
    T, J = TINY_FRAMES, topo.n_joints
    base = rng.normal(0.0, 0.3, size=(J, 3)) + np.array([0.0, 0.0, 2.5])
    walk = np.cumsum(rng.normal(0.0, 0.004, size=(T, J, 3)), axis=0)
    pos = base + walk + rng.normal(0.0, 0.005, size=(T, J, 3))
    if clean:
        still = base + rng.normal(0.0, 0.002, size=(T, J, 3))
        return SkeletonSequence(positions=still, topology=topo, fps=30.0)
    pos[40:44, J - 1] += 0.6  # a sustained glitch on the last joint
    pos[10:13, 5] = np.nan  # a gap
    states = np.full((T, J), TrackingState.TRACKED, dtype=np.int8)
    states[20:25, 7] = TrackingState.INFERRED
    states[60:62, 9] = TrackingState.NOT_TRACKED
    return SkeletonSequence(positions=pos, topology=topo, fps=30.0, tracking_state=states)


class _Watch:
    """Listens to numba's compile events: the time spent compiling, and a first-compile
    callback (top-level compilations only; nested ones are inside their caller's)."""

    def __init__(self, on_compile: Callable[[], Any] | None) -> None:
        self.on_compile = on_compile
        self.depth = 0
        self.started = 0.0
        self.seconds = 0.0
        self.count = 0

    def listener(self) -> Any:
        from numba.core import event

        watch = self

        class Listener(event.Listener):
            def on_start(self, ev: Any) -> None:
                if watch.depth == 0:
                    watch.started = time.perf_counter()
                    if watch.count == 0 and watch.on_compile is not None:
                        watch.on_compile()
                watch.depth += 1
                watch.count += 1

            def on_end(self, ev: Any) -> None:
                watch.depth -= 1
                if watch.depth == 0:
                    watch.seconds += time.perf_counter() - watch.started

        return Listener()


def _run_tiny(method: str) -> None:
    from tobitkf.smoothing.live import LiveSmoother, live_methods
    from tobitkf.smoothing.untangle import untangle_sequences

    seq = tiny_recording()
    smooth(seq, method=method)
    # several people in pixels are untangled before any method runs: its compiled loops
    # (two people: one compiled loop; three or more: compiled steps called from Python
    # frame by frame, which the cache must hold on their own)
    px = seq.positions[..., :2] * 500
    people3 = [seq.replace(positions=px + 100 * b, units="px", tracking_state=None)
               for b in range(3)]  # fmt: skip
    untangle_sequences(people3)
    people = people3[:2]
    untangle_sequences(people)
    try:  # the method on them: 2-D, its gates from the recording (robust's)
        smooth(people, method=method)
    except ValueError:  # a method whose defaults mean nothing in pixels (metres)
        pass
    # and one where nothing fails: some kernels have a path of their own for it (the
    # robust smoother's without shared errors)
    smooth(tiny_recording(clean=True), method=method)
    if get_method(method).live is not None and method in live_methods():
        live = LiveSmoother(seq.topology, method=method, fps=30.0)
        for t in range(5):
            live.update(seq.positions[t], tracking_state=seq.tracking_state[t])
        # several people in one stream, untangled frame by frame: in metres, and in the
        # pixels of a pose estimator, measured on the stream itself
        live = LiveSmoother(seq.topology, method=method, fps=30.0)
        for t in range(5):
            live.update(np.stack([seq.positions[t] + b for b in range(3)]))
        live = LiveSmoother(seq.topology, method=method, fps=30.0, gates_from="stream")
        try:
            for t in range(40):
                live.update(np.stack([p.positions[t] for p in people3]))
        except ValueError:  # as above: defaults in metres
            pass


def warm(method: str, on_compile: Callable[[], Any] | None = None) -> float:
    """Run ``method`` on :func:`tiny_recording` so that its kernels are compiled and
    cached; returns the seconds spent compiling (0 when everything came from the cache).

    ``on_compile`` is called once, when the first kernel starts compiling (e.g. to tell
    the person waiting why).
    """
    get_method(method)  # an unknown name fails here, with the list of methods
    with on_first_compile(on_compile) as watch:
        _run_tiny(method)
    return watch.seconds


@contextmanager
def on_first_compile(callback: Callable[[], Any] | None) -> Iterator[_Watch]:
    """Call ``callback`` once, when the first kernel starts compiling inside the block
    (a command that runs methods says why the first run on a machine waits); the block
    gets the :class:`_Watch`, whose ``seconds`` are the time spent compiling."""
    from numba.core import event

    watch = _Watch(callback)
    with event.install_listener("numba:compile", watch.listener()):
        yield watch


def _warm_in_child(method: str) -> tuple[str, float]:
    return method, warm(method)


def warmup(
    methods: Iterable[str] | None = None,
    jobs: int = 1,
    on_done: Callable[[str, float], Any] | None = None,
) -> dict[str, float]:
    """Compile and cache the kernels of ``methods`` (default: every registered method).

    ``jobs`` > 1 warms methods in that many new processes at once (numba compiles in one
    thread; the cache is shared on disk). ``on_done(method, seconds)`` is called as each
    method is ready. Returns the compile seconds per method.
    """
    names = list(method_names() if methods is None else methods)
    for name in names:
        get_method(name)
    done: dict[str, float] = {}

    def record(name: str, seconds: float) -> None:
        done[name] = seconds
        if on_done is not None:
            on_done(name, seconds)

    if jobs <= 1 or len(names) <= 1:
        for name in names:
            record(name, warm(name))
        return done
    # user methods registered in this process would be unknown to a fresh one
    builtin = [n for n in names if get_method(n).run.__module__.startswith("tobitkf.")]
    # the default (the longest compile) first, the causal default (which shares most of
    # its kernels, cached by then) last, so that two processes seldom compile one kernel
    last = {DEFAULT_METHOD: 0, DEFAULT_LIVE_METHOD: 2}
    builtin.sort(key=lambda n: last.get(n, 1))
    with ProcessPoolExecutor(max_workers=jobs, mp_context=get_context("spawn")) as pool:
        futures = [pool.submit(_warm_in_child, n) for n in builtin]
        for fut in as_completed(futures):
            record(*fut.result())
    for name in names:
        if name not in done:  # registered in this process only: warmed here
            record(name, warm(name))
    return {n: done[n] for n in names}

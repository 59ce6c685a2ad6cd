"""Kernels compiled ahead of the work: ``tobitkf warmup`` and the notice of ``smooth``.

Compilation is observed through numba itself, not through our timings: its compile events
(a kernel that compiles during a call is a kernel the cache did not have), and the
signatures its dispatchers hold (a call with a signature its dispatcher does not hold yet
is one that an empty cache would have to compile).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("click")

import tobitkf as tk
from conftest import data_file
from tobitkf.smoothing.warmup import tiny_recording, warm


def test_tiny_recording_exercises_the_rules():
    seq = tiny_recording()
    out = tk.smooth(seq)  # robust: the glitch is rejected, the gap and INFERRED are there
    assert (out.sample_state == tk.SampleState.REJECTED).any()
    assert (out.sample_state == tk.SampleState.MISSING).any()
    assert (seq.tracking_state == tk.TrackingState.INFERRED).any()


COVER = r"""
import json, sys
import numpy as np
import tobitkf as tk
from numba.core import event
from numba.core.registry import CPUDispatcher
from tobitkf.smoothing.warmup import warm


def signatures():
    # every (kernel, signature) the package's dispatchers hold: compiled, or loaded from
    # the cache (both add the signature), including modules imported since the last look
    held = set()
    for name, module in list(sys.modules.items()):
        if name.startswith("tobitkf") and module is not None:
            for obj in list(vars(module).values()):
                if isinstance(obj, CPUDispatcher):
                    f = obj.py_func
                    held |= {(f.__module__, f.__qualname__, str(sig)) for sig in obj.overloads}
    return held


class Compiles(event.Listener):
    # a safety net for kernels that are no module's attribute: whatever compiles after
    # warm() was in neither warm()'s signatures nor the cache
    seen = []

    def on_start(self, ev):
        self.seen.append(("compiled", ev.data["dispatcher"].py_func.__qualname__, ""))

    def on_end(self, ev):
        pass


method, files = sys.argv[1], sys.argv[2:]
warm(method)
before = signatures()
event.register("numba:compile", Compiles())
for path in files:
    for seq in tk.load(path):
        tk.smooth(seq, method=method)
# two people of a pose estimator, in pixels: untangled before the method
from tobitkf.smoothing.untangle import untangle_sequences
seq = tk.load(files[0])[0]
people = [seq.replace(positions=seq.positions[:, :, :2] * 300 + 50 * b, units="px",
                      tracking_state=None) for b in range(3)]
untangle_sequences(people)
if method == "robust":  # its gates from the recording, in pixels
    tk.smooth(people, method=method)
if method == "robust_online":  # a live stream of them, untangled frame by frame
    live = tk.LiveSmoother(seq.topology, fps=30.0, gates_from="stream")
    for t in range(40):
        live.update(np.stack([p.positions[t] for p in people]))
if tk.methods()[method].live is not None and method in tk.live_methods():
    seq = tk.load(files[0])[0]
    live = tk.LiveSmoother(seq.topology, method=method, fps=seq.fps or 30.0)
    for t in range(3):
        live.update(seq.positions[t], tracking_state=seq.tracking_state[t])
print(json.dumps(sorted(signatures() - before) + Compiles.seen))
"""


COVERED = ["robust", "robust_online", "atkf", "tkfc", "kinect", "one_euro"]


@pytest.fixture(scope="module")
def covered(request):
    """Per method of :data:`COVERED` whose test was selected, what the :data:`COVER` run
    printed. Each run is its own process in the usual cache (filled by ``make install``;
    a kernel missing there is compiled into it, so the answer does not depend on it):
    the signatures the dispatchers gained after :func:`warm` are those an empty cache
    would compile then. Two runs at a time (the 2 cores of CI)."""
    from concurrent.futures import ThreadPoolExecutor

    test = test_warming_on_the_tiny_recording_covers_real_files.__name__
    names = {item.name for item in request.session.items}
    methods = [m for m in COVERED if f"{test}[{m}]" in names]

    files = [
        data_file(rel)
        for rel in (
            "kimore/JointPositionExercise1.csv",
            "keraal/G3-Kinect-CTK-P1T1-Unknown-C-0.txt",
            "krajjat/sequence_ainhoa_trimmed.tsv",
            "cmu-mocap/scaled_131_01.bvh",
        )
    ]

    def run(method: str) -> subprocess.CompletedProcess:
        env = dict(os.environ, PYTHONWARNINGS="ignore")
        return subprocess.run([sys.executable, "-c", COVER, method, *map(str, files)],
                              env=env, capture_output=True, text=True, timeout=600)  # fmt: skip

    with ThreadPoolExecutor(max_workers=2) as pool:
        return dict(zip(methods, pool.map(run, methods), strict=True))


@pytest.mark.realdata
@pytest.mark.parametrize("method", COVERED)
def test_warming_on_the_tiny_recording_covers_real_files(method, covered):
    # after warm(), real recordings (other lengths, tracking states or none, other
    # formats, live frames) call no kernel with a signature warm() did not give it
    res = covered[method]
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout.splitlines()[-1]) == []


def test_warm_reports_compilation_once_and_only_when_compiling():
    calls = []
    warm("kf")  # now cached, whatever it was before
    assert warm("kf", on_compile=lambda: calls.append(1)) == 0.0
    assert calls == []


def _cli(args: list[str], cache: Path, cwd: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    code = "import sys; from tobitkf.app.cli import main; sys.exit(main(sys.argv[1:]))"
    return subprocess.run([sys.executable, "-c", code, *args], env=env, cwd=cwd,
                          capture_output=True, text=True, timeout=300)  # fmt: skip


@pytest.mark.slow
def test_empty_cache_compiles_once_says_so_then_loads(tmp_path):
    from concurrent.futures import ThreadPoolExecutor

    cache = tmp_path / "numba-cache"
    seq = tiny_recording()
    tk.save([seq], tmp_path / "rec.csv", format="csv")
    cache2 = tmp_path / "other-cache"

    def smooth_twice() -> tuple[subprocess.CompletedProcess, ...]:
        first = _cli(["smooth", "rec.csv", "-o", "out", "-m", "kf"], cache, tmp_path)
        args = ["smooth", "rec.csv", "-o", "out", "-m", "kf", "--overwrite"]
        return first, _cli(args, cache, tmp_path)

    def warm_twice() -> tuple[subprocess.CompletedProcess, ...]:
        return tuple(_cli(["warmup", "-m", "kf", "-j", "1"], cache2, tmp_path) for _ in range(2))

    with ThreadPoolExecutor(max_workers=2) as pool:  # two caches, independent: 2 cores
        smoothed, warmed = pool.submit(smooth_twice), pool.submit(warm_twice)
        (first, again), (w1, w2) = smoothed.result(), warmed.result()
    assert first.returncode == 0, first.stderr
    assert "compiling the kernels of kf" in first.stderr
    assert any(cache.rglob("*.nbi"))  # numba wrote its cache
    assert again.returncode == 0, again.stderr
    assert "compiling" not in again.stderr
    # the warmup command in a new cache: kf compiles (seconds > 0), then nothing does
    assert w1.returncode == 0 and w2.returncode == 0, w1.stderr + w2.stderr
    row1 = next(ln for ln in w1.stdout.splitlines() if " kf " in ln)
    row2 = next(ln for ln in w2.stdout.splitlines() if " kf " in ln)
    assert float(row1.split()[-2]) > 0
    assert float(row2.split()[-2]) == 0


def test_warmup_rejects_unknown_methods():
    from tobitkf.smoothing.warmup import warmup

    with pytest.raises(ValueError, match="unknown method"):
        warmup(["no-such-method"])


def test_help_imports_no_numerics():
    # `tobitkf --help` must stay quick: the method lists are read only when a command
    # runs (the registry imports numpy, scipy and every method module)
    code = (
        "import sys\n"
        "from tobitkf.app.cli import main\n"
        "main(['--help'])\n"
        "loaded = [m for m in ('tobitkf.smoothing.api', 'scipy', 'numba') if m in sys.modules]\n"
        "print(loaded)\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert res.stdout.splitlines()[-1] == "[]"


def test_a_read_only_installation_caches_in_a_temporary_folder(tmp_path):
    # site-packages read-only and no writable home: numba found no place for its cache
    # and every kernel failed at import ("no locator available"). numba is told here to
    # look only where NUMBA_CACHE_DIR points, which is unset: the same situation
    numba_config = pytest.importorskip("numba").config
    if not hasattr(numba_config, "CACHE_LOCATOR_CLASSES"):
        pytest.skip("this numba cannot be told where to look for a cache (an older numba)")
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env.update(
        NUMBA_CACHE_LOCATOR_CLASSES="UserProvidedCacheLocator",
        TMPDIR=str(tmp_path),
        PYTHONDONTWRITEBYTECODE="1",
    )
    code = (
        "import numpy as np, tobitkf as tk\n"
        "y = np.cumsum(np.random.default_rng(0).normal(size=(40, 25, 3)) * 0.01, 0)\n"
        "out = tk.smooth(tk.SkeletonSequence(y, 'kinect_v2', fps=30), 'one_euro')\n"
        "print(np.isfinite(out.positions).all())\n"
    )
    run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         timeout=600)  # fmt: skip
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.strip() == "True"
    assert "NUMBA_CACHE_DIR" in run.stderr and str(tmp_path) in run.stderr
    cached = list(tmp_path.glob("tobitkf-numba-*/**/*.nbi"))
    assert cached, "nothing was cached in the fallback folder"


@pytest.mark.parametrize("command", ["evaluate", "report", "benchmark", "demo"])
def test_commands_that_run_methods_say_when_kernels_compile(command):
    # only smooth said why a first run waits; demo sat silent for two minutes on a fresh
    # installation. The command runs inside _noticing_compiles, and a kernel compiled
    # inside it (two fresh functions here) gets the notice, once
    from numba import njit

    from tobitkf.app.commands import _common, app

    callback = app.commands[command].callback
    assert callback.__code__ is _common._noticing_compiles(len).__code__  # the wrapper
    fresh = [njit(lambda x, k=k: x + k) for k in (1, 2)]  # compiled on their first call
    said = []
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(_common.err_console, "print", lambda *a, **k: said.append(str(a[0])))
        _common._noticing_compiles(lambda: [f(1.0) for f in fresh])()
    assert len(said) == 1 and said[0].startswith("compiling the smoothers' kernels")

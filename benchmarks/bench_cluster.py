"""Files per second of ``tobitkf smooth`` locally and on Dask, and an NTU-120 projection.

    .venv/bin/python benchmarks/bench_cluster.py                  # 5000 files (make bench)
    .venv/bin/python benchmarks/bench_cluster.py --files 200      # a quick try
    .venv/bin/python benchmarks/bench_cluster.py --data /big/ntu-like --keep   # reuse it

Data: an NTU-like data set of ``--files`` ``.skeleton`` files written with the project's
own NTU writer (:mod:`tobitkf.evaluation.ntu_like`: 60–300 frames, one or two bodies,
glitches from the Kinect-like corruption model). Each run is the command itself, start-up
included, timed from outside: serial (``-j 1``), ``-j 2``, ``--cluster local --workers
2`` and ``--cluster tcp://...`` against a scheduler and two single-threaded workers
started by hand (``dask scheduler``, ``dask worker``). Every run's outputs are checked
byte for byte against the serial run's (by sha256).

Projection for NTU RGB+D 120 (114,480 files) on 8, 32 and 128 workers:
``start-up + N x c / W + tasks x o``, where ``c`` is the per-file cost measured on the
hand-started cluster (wall time less start-up, times its workers, over the files: the
cost of a file on a busy worker, I/O included), ``o`` the scheduler's cost per task
(measured: empty tasks through the same scheduler) and ``tasks`` the number of tasks
``tobitkf`` makes for N files on W workers. It assumes the shared storage keeps up with W
workers (not measured here) and files like these (the real NTU files have 30–300 frames).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

NTU120 = 114_480
PROJECT_WORKERS = (8, 32, 128)
MARKER = "bench-cluster.json"


def _marker(folder: Path) -> Path:
    """The file that says what ``folder`` holds: beside it, not in it (``tobitkf smooth
    FOLDER`` takes every file in the folder as an input)."""
    return folder.parent / f".{folder.name}.{MARKER}"


def _part(args: tuple[str, int, int]) -> int:
    from tobitkf.evaluation.ntu_like import write_ntu_like

    folder, start, n = args
    return len(write_ntu_like(folder, n, start=start))


def make_dataset(folder: Path, n: int, workers: int = 2) -> None:
    """``n`` NTU-like files in ``folder`` (kept when a previous call wrote the same)."""
    marker = _marker(folder)
    if marker.exists() and folder.is_dir() and json.loads(marker.read_text()) == {"files": n}:
        print(f"data set: {n} files in {folder} (reused)", flush=True)
        return
    marker.unlink(missing_ok=True)  # until the folder is complete again
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    t0 = time.perf_counter()
    step = 100
    chunks = [(str(folder), s, min(step, n - s)) for s in range(0, n, step)]
    with ProcessPoolExecutor(workers) as pool:
        for _ in pool.map(_part, chunks):
            pass
    marker.write_text(json.dumps({"files": n}))
    size = sum(p.stat().st_size for p in folder.rglob("*.skeleton"))
    print(f"data set: {n} files, {size / 1e9:.2f} GB, written in "
          f"{time.perf_counter() - t0:.0f} s", flush=True)  # fmt: skip


def _dask_command() -> list[str]:
    exe = Path(sys.executable).parent / "dask"
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "dask"]


class HandStarted:
    """``dask scheduler`` and ``dask worker`` processes started by hand on this machine."""

    def __init__(self, workers: int, tmp: Path) -> None:
        self.file = tmp / "scheduler.json"
        self.procs = []
        log = open(tmp / "dask.log", "w")
        self.log = log
        dask = _dask_command()
        self.procs.append(subprocess.Popen(
            [*dask, "scheduler", "--port", "0", "--no-dashboard", "--scheduler-file",
             str(self.file)], stdout=log, stderr=log))  # fmt: skip
        deadline = time.monotonic() + 60
        while not self.file.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        for _ in range(workers):
            self.procs.append(subprocess.Popen(
                [*dask, "worker", "--nthreads", "1", "--nworkers", "1", "--no-dashboard",
                 "--scheduler-file", str(self.file)], stdout=log, stderr=log))  # fmt: skip
        from distributed import Client

        with Client(scheduler_file=str(self.file)) as c:
            c.wait_for_workers(workers, timeout=120)
            self.address = c.scheduler.address

    def task_overhead(self, n: int = 2000) -> float:
        """Seconds per task of the scheduler: ``n`` empty tasks submitted and gathered."""
        from distributed import Client

        with Client(self.address) as c:
            c.gather(c.map(_noop, range(200), pure=False))  # warm-up
            t0 = time.perf_counter()
            c.gather(c.map(_noop, range(n), pure=False))
            return (time.perf_counter() - t0) / n

    def stop(self) -> None:
        for p in reversed(self.procs):
            p.terminate()
        for p in self.procs:
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()
        self.log.close()


def _noop(x: int) -> int:
    return x


def smooth(data: Path, out: Path, *extra: str) -> tuple[float, list[dict]]:
    """Wall time of ``tobitkf smooth DATA -o OUT *extra`` and its JSON summary."""
    cmd = [sys.executable, "-m", "tobitkf", "smooth", str(data), "-o", str(out), "--json", *extra]
    t0 = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    sec = time.perf_counter() - t0
    if done.returncode != 0:
        try:  # with --json the files that failed are in the summary, not on stderr
            failed = [s for s in json.loads(done.stdout) if not s.get("ok", True)]
        except ValueError:
            failed = []
        why = "\n".join(f"{s.get('source')}: {s.get('error')}" for s in failed[:20])
        raise RuntimeError(
            f"{' '.join(cmd)} failed ({done.returncode}, {len(failed)} file(s)):\n{why}\n"
            f"{done.stderr[-3000:]}"
        )
    return sec, json.loads(done.stdout)


def output_hashes(out: Path) -> dict[str, str]:
    return {
        p.relative_to(out).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(out.rglob("*.skeleton"))
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--files", type=int, default=5000, help="files in the data set")
    ap.add_argument("--workers", type=int, default=2, help="Dask workers (default 2)")
    ap.add_argument("--data", type=Path, help="folder of the data set (default: temporary)")
    ap.add_argument("--keep", action="store_true", help="keep the data set in --data")
    ap.add_argument("--markdown", action="store_true", help="end with the README's tables")
    args = ap.parse_args()
    from tobitkf.app.cluster import files_per_task

    tmp = Path(tempfile.mkdtemp(prefix="bench-cluster-"))
    data = args.data or tmp / "data"
    W = args.workers
    try:
        make_dataset(data, args.files)
        one = tmp / "one"  # a single file: the start-up of a run
        (one / "S001").mkdir(parents=True)
        first = sorted((data / "S001").glob("*.skeleton"))[0]
        shutil.copy(first, one / "S001" / first.name)
        cluster = HandStarted(W, tmp)
        try:
            overhead = cluster.task_overhead()
            print(f"scheduler overhead: {overhead * 1e3:.2f} ms per task", flush=True)
            runs = {
                "serial (`-j 1`)": ("-j", "1"),
                f"`-j {W}`": ("-j", str(W)),
                f"`--cluster local --workers {W}`": ("--cluster", "local", "--workers", str(W)),
                f"`--cluster tcp://...`, {W} workers by hand": ("--cluster", cluster.address),
            }
            rows, reference = [], None
            for label, extra in runs.items():
                out = tmp / "out"
                sec, summary = smooth(data, out, *extra)
                ok = [s for s in summary if s["ok"]]
                jf = sum(s["bodies"] * s["frames"] * s["joints"] for s in ok)
                hashes = output_hashes(out)
                reference = reference or hashes
                same = hashes == reference and len(hashes) == args.files
                shutil.rmtree(out)
                rows.append((label, len(ok), sec, len(ok) / sec, jf / sec, same))
                print(f"{label}: {len(ok)}/{args.files} files in {sec:.1f} s, "
                      f"{len(ok) / sec:.1f} files/s, {jf / sec:.3g} joint-frames/s, "
                      f"outputs = serial: {same}", flush=True)  # fmt: skip
            start, _ = smooth(one, tmp / "out-one", "--cluster", cluster.address)
            shutil.rmtree(tmp / "out-one")
        finally:
            cluster.stop()
        cost = (rows[-1][2] - start) * W / args.files
        print(f"start-up {start:.1f} s, per-file cost {cost * 1e3:.0f} ms on a busy worker")
        projection = []
        for w in PROJECT_WORKERS:
            tasks = -(-NTU120 // files_per_task(NTU120, w))
            sec = start + NTU120 * cost / w + tasks * overhead
            projection.append((w, NTU120 // tasks, tasks, sec))
            print(f"NTU-120 on {w} workers: {tasks} tasks, {sec / 60:.0f} min")
        if args.markdown:
            print_markdown(rows, args.files, W, start, cost, overhead, projection)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        if args.data is not None and not args.keep:
            shutil.rmtree(args.data, ignore_errors=True)
            _marker(args.data).unlink(missing_ok=True)


def print_markdown(rows, n, W, start, cost, overhead, projection) -> None:
    from bench_filters import machine  # benchmarks/ is on the path when this script runs

    print("\x1e")  # docs_results keeps what follows
    print(f"{n} NTU-like files (60–300 frames, 1–2 bodies, Kinect-like glitches), default "
          f"method, start-up included; measured {machine()}.")  # fmt: skip
    print()
    print("| run | files | seconds | files / s | joint-frames / s | outputs = serial |")
    print("|---|---|---|---|---|---|")
    for label, ok, sec, fps, jfs, same in rows:
        print(f"| {label} | {ok} | {sec:.0f} | {fps:.1f} | {jfs:.2g} | {'yes' if same else 'NO'} |")
    print()
    print(f"Projection for NTU RGB+D 120 ({NTU120:,} files) from the hand-started cluster: "
          f"start-up {start:.1f} s, {cost * 1e3:.0f} ms per file on a busy worker, "
          f"{overhead * 1e3:.2f} ms of scheduler time per task; shared storage assumed to "
          f"keep up.")  # fmt: skip
    print()
    print("| workers | files per task | tasks | projected time |")
    print("|---|---|---|---|")
    for w, per, tasks, sec in projection:
        print(f"| {w} | {per} | {tasks} | {sec / 60:.0f} min |")


if __name__ == "__main__":
    main()

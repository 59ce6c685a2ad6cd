"""A new user's rough edges (issue 14, points 9-12): clear messages instead of tracebacks,
outputs that never replace someone else's file, --format for every input, progress, units
and a report that reads well in a browser."""

from __future__ import annotations

import builtins
import io
import json
import os
import shutil
import stat
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

click = pytest.importorskip("click")
from click.testing import CliRunner  # noqa: E402
from rich.console import Console  # noqa: E402
from rich.text import Text  # noqa: E402

from test_cli import _recording  # noqa: E402
from tobitkf.app.commands import _common as commands  # noqa: E402
from tobitkf.app.commands import app  # noqa: E402
from tobitkf.io import load, save  # noqa: E402

ROOT = os.geteuid() == 0  # permissions do not apply to root


def _invoke(*args: str):
    res = CliRunner().invoke(app, [str(a) for a in args])
    assert "Traceback" not in res.output, res.output
    return res


def _clean_failure(res, message: str, status: int = 1) -> None:
    assert res.exit_code == status, res.output
    assert message in res.output, res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    assert "Errno" not in res.output, res.output


def _denies(path: Path) -> bool:
    """True when chmod really denies access here (not root, not a permissive filesystem)."""
    try:
        if path.is_dir():
            (path / ".probe").write_text("x")
            (path / ".probe").unlink()
        else:
            path.read_bytes()
    except PermissionError:
        return True
    return False


# --------------------------------------------------------------------------- point 9
def test_unwritable_outputs_are_one_message_before_any_work(tmp_path, monkeypatch):
    track = tmp_path / "a.csv"
    save([_recording()], track, format="csv")
    blocker = tmp_path / "afile"
    blocker.write_text("not a folder")

    def no_work(*args, **kwargs):  # the check must come before the work
        raise AssertionError("work started before the output was checked")

    monkeypatch.setattr("tobitkf.app.report.track_report", no_work)
    monkeypatch.setattr("tobitkf.app.demo.run_demo", no_work)
    monkeypatch.setattr("tobitkf.app.batch.run_jobs", no_work)
    monkeypatch.setattr("tobitkf.evaluation.evaluate.evaluate_without_truth", no_work)
    monkeypatch.setattr("tobitkf.paper.oscillator.oscillator_experiment", no_work)
    sub = blocker / "sub"
    # -o an existing file: no FileExistsError [Errno 17]; once, not once per input
    save([_recording(seed=1)], tmp_path / "b.csv", format="csv")
    res = _invoke("smooth", track, tmp_path / "b.csv", "-o", blocker)
    _clean_failure(res, "a file of that name exists")
    assert res.output.count("cannot write") == 1
    _clean_failure(_invoke("smooth", track, "-o", sub), "part of the path is a file")
    _clean_failure(_invoke("report", track, "-o", sub / "r.html"), "cannot write the report")
    _clean_failure(_invoke("evaluate", track, "-o", sub), "cannot write results.json")
    _clean_failure(_invoke("demo", "-o", sub), "cannot write the demo's files")
    _clean_failure(
        _invoke("reproduce", "oscillator", "--runs", "1", "--out", sub), "cannot write the figures"
    )


@pytest.mark.skipif(ROOT, reason="permissions do not apply to root")
def test_smooth_into_a_read_only_folder_is_one_message(tmp_path):
    track = tmp_path / "a.csv"
    save([_recording()], track, format="csv")
    save([_recording(seed=1)], tmp_path / "b.csv", format="csv")
    out = tmp_path / "ro"
    out.mkdir()
    out.chmod(0o500)
    try:
        if not _denies(out):
            pytest.skip("chmod does not deny writing here")
        res = _invoke("smooth", track, tmp_path / "b.csv", "-o", out)
        _clean_failure(res, "permission denied")
        assert res.output.count("cannot write") == 1 and "a.csv" not in res.output
    finally:
        out.chmod(0o700)


def test_reproduce_oscillator_zero_runs_is_a_usage_error():
    res = _invoke("reproduce", "oscillator", "--runs", "0")
    _clean_failure(res, "--runs", status=2)


def test_missing_matplotlib_names_the_extra(tmp_path, monkeypatch):
    track = tmp_path / "a.csv"
    save([_recording()], track, format="csv")
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib -> ImportError
    for args in (  # the demo writes what needs no figure (its own test)
        ["report", track, "-o", tmp_path / "r.html", "--methods", "raw"],
        ["reproduce", "oscillator", "--runs", "1", "--steps", "5", "--out", tmp_path / "f"],
    ):
        res = _invoke(*args)
        _clean_failure(res, "pip install 'tobitkf[plot]'")


def _deny_open(monkeypatch, target: Path) -> None:
    """Simulate an unreadable file (root reads everything): open() of it is refused."""
    real_open = builtins.open

    def fake_open(file, *args, **kwargs):
        if isinstance(file, (str, os.PathLike)) and Path(file).name == target.name:
            raise PermissionError(13, "Permission denied", str(file))
        return real_open(file, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", fake_open)


def test_unreadable_file_is_reported_as_unreadable(tmp_path, monkeypatch):
    track = tmp_path / "locked.csv"
    save([_recording()], track, format="csv")
    if not ROOT:
        track.chmod(0)
        if _denies(track):
            res = _invoke("evaluate", track, "--methods", "raw")
            _clean_failure(res, "permission denied")
        track.chmod(stat.S_IRUSR | stat.S_IWUSR)
    _deny_open(monkeypatch, track)
    res = _invoke("evaluate", track, "--methods", "raw")
    _clean_failure(res, "cannot read it: permission denied")
    assert "unrecognised content" not in res.output
    res = _invoke("smooth", track, "-o", tmp_path / "out")
    _clean_failure(res, "cannot read it: permission denied")


def test_folder_walk_names_what_it_cannot_follow(tmp_path, monkeypatch):
    src = tmp_path / "in"
    (src / "locked").mkdir(parents=True)
    save([_recording()], src / "a.csv", format="csv")
    save([_recording()], src / "locked" / "b.csv", format="csv")
    (src / "dangling.csv").symlink_to(src / "gone.csv")
    (src / "loop.csv").symlink_to(src / "loop.csv")
    real_scandir = os.scandir

    def scandir(path="."):  # simulate an unreadable subfolder (root reads everything)
        if Path(path).name == "locked":
            raise PermissionError(13, "Permission denied", str(path))
        return real_scandir(path)

    monkeypatch.setattr(os, "scandir", scandir)
    res = _invoke("smooth", src, "-o", tmp_path / "out")
    assert res.exit_code == 0, res.output
    text = " ".join(res.output.split())
    assert "locked: cannot read this folder: permission denied" in text
    assert "dangling.csv: dangling symbolic link" in text
    assert "loop.csv: symbolic link loop" in text
    assert (tmp_path / "out" / "a.robust.csv").exists()


def test_smooth_never_replaces_a_foreign_file_and_skips_its_own_outputs(tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    save([_recording()], src / "a.csv", format="csv")
    foreign = src / "a.robust.csv"
    foreign.write_text("my own notes\n")
    res = _invoke("smooth", src / "a.csv", "-o", src)
    assert res.exit_code == 1 and "not a tobitkf output" in " ".join(res.output.split())
    assert foreign.read_text() == "my own notes\n"
    res = _invoke("smooth", src / "a.csv", "-o", src, "--overwrite")
    assert res.exit_code == 0, res.output
    assert foreign.read_text() != "my own notes\n"
    # in place, twice: the first run's output is an input no more (no a.robust.robust.csv)
    for _ in range(2):
        res = _invoke("smooth", src, "-o", src)
        assert res.exit_code == 0, res.output
    assert sorted(p.name for p in src.iterdir()) == [
        "a.csv",
        "a.json",
        "a.robust.csv",
        "a.robust.json",
        "tobitkf-manifest.jsonl",  # the run's manifest, not taken as an input either
    ]
    assert "tobitkf outputs of an earlier run" in " ".join(res.output.split())
    assert "not recordings" not in " ".join(res.output.split())


def test_a_recording_named_like_an_output_in_a_format_tobitkf_never_writes_is_smoothed(tmp_path):
    """``<name>.<method><ext>`` marks an earlier output only for extensions tobitkf
    writes: 'kinect' is a method and a natural word in a Kinect recording's name."""
    from test_io_mocap import BVH_SMALL

    src = tmp_path / "in"
    src.mkdir()
    text = BVH_SMALL.format(root_order="Zrotation Yrotation Xrotation", r0="0 0 0", r1="0 0 9")
    (src / "dance.kinect.bvh").write_text(text)
    (src / "walk.sgf.bvh").write_text(text)
    res = _invoke("smooth", src, "-o", tmp_path / "out")
    assert res.exit_code == 0, res.output
    outputs = sorted(p.name for p in (tmp_path / "out").glob("*.csv"))
    assert outputs == ["dance.kinect.robust.csv", "walk.sgf.robust.csv"]
    assert "earlier run" not in " ".join(res.output.split())


def _plain_c3d(path: Path) -> None:
    """A recording as a plain C3D writer (the c3d package) writes it: no TOBITKF group."""
    c3d = pytest.importorskip("c3d")
    rec = _recording()
    w = c3d.Writer(point_rate=30.0, point_scale=-1.0, point_units="m")
    no_analog = np.zeros((0, 0), dtype=np.float32)
    pts = np.zeros((rec.n_frames, rec.n_joints, 5), dtype=np.float32)
    pts[..., :3] = rec.positions
    w.add_frames([(frame, no_analog) for frame in pts])
    w.set_point_labels(list(rec.joint_names))
    with open(path, "wb") as fh, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the library's note on the empty analog group
        w.write(fh)


def test_a_c3d_recording_named_like_an_output_is_smoothed_and_outputs_are_passed_over(tmp_path):
    """C3D keeps the provenance: ``subject01.kinect.c3d`` from a plain C3D writer is a
    recording ('kinect' is a method name); tobitkf's own ``x.kinect.c3d`` (provenance:
    kinect) is an earlier output, passed over when smoothing the folder in place."""
    src = tmp_path / "in"
    src.mkdir()
    _plain_c3d(src / "subject01.kinect.c3d")
    _plain_c3d(src / "x.c3d")
    for run in range(2):
        res = _invoke("smooth", src, "-o", src, "-m", "kinect", "-f", "c3d")
        assert res.exit_code == 0, res.output
        text = " ".join(res.output.split())
        assert ("earlier run" in text) == (run == 1), text
    assert sorted(p.name for p in src.iterdir()) == [
        "subject01.kinect.c3d",
        "subject01.kinect.kinect.c3d",
        "tobitkf-manifest.jsonl",
        "x.c3d",
        "x.kinect.c3d",
    ]
    assert load(src / "x.kinect.c3d")[0].metadata["provenance"]["method"] == "kinect"


def test_outputs_get_the_umask_mode(tmp_path):
    save([_recording()], tmp_path / "a.csv", format="csv")
    old = os.umask(0o022)
    try:
        res = _invoke("smooth", tmp_path / "a.csv", "-o", tmp_path / "out")
    finally:
        os.umask(old)
    assert res.exit_code == 0, res.output
    for f in (tmp_path / "out").iterdir():
        assert stat.S_IMODE(f.stat().st_mode) == 0o644, f


# --------------------------------------------------------------------------- point 10
def _terminal(monkeypatch) -> io.StringIO:
    buf = io.StringIO()
    console = Console(file=buf, force_terminal=True, width=120)
    monkeypatch.setattr(commands, "err_console", console)
    return buf


@pytest.mark.parametrize("width", [50, 60, 100])
def test_the_progress_line_keeps_counts_and_time_in_a_narrow_terminal(monkeypatch, width):
    """What a long run shows: the files done of all, the frames, the elapsed time; the
    bar is dropped and the name shortened first."""
    buf = io.StringIO()
    monkeypatch.setattr(
        commands, "err_console", Console(file=buf, force_terminal=True, width=width)
    )
    with commands._progress(False, "{task.fields[frames]} frames", transient=False) as p:
        task = p.add_task("smoothing (robust_online)", total=100000, frames=0)
        p.update(task, advance=12345, frames=1234567)
    last = Text.from_ansi(buf.getvalue().split("\r")[-1]).plain.splitlines()[-1]
    assert len(last) <= width
    for shown in ("12345/100000", "1234567 frames", "0:00:0"):
        assert shown in last, (shown, last)
    assert ("━" in last) == (width >= commands._BAR_MIN_WIDTH)


def test_progress_on_a_terminal_for_evaluate_benchmark_and_fit(tmp_path, monkeypatch):
    track = tmp_path / "a.csv"
    save([_recording()], track, format="csv")
    buf = _terminal(monkeypatch)
    assert _invoke("evaluate", track, "--methods", "raw,kf").exit_code == 0
    assert "a.csv" in buf.getvalue() and "2/2" in buf.getvalue()
    buf = _terminal(monkeypatch)
    res = _invoke("benchmark", "--seeds", "2", "--duration", "2", "--methods", "raw,kf")
    assert res.exit_code == 0, res.output
    assert "seed 1" in buf.getvalue() and "2/2" in buf.getvalue()
    buf = _terminal(monkeypatch)
    assert _invoke("fit", track, "--per-joint").exit_code == 0
    assert "25/25" in buf.getvalue()
    buf = _terminal(monkeypatch)  # report: each method, then the drawing
    res = _invoke("report", track, "--methods", "raw,kf", "-o", tmp_path / "r.html", "--no-gif")
    assert res.exit_code == 0, res.output
    assert "a.csv" in buf.getvalue() and "drawing figures" in buf.getvalue()
    assert "2/3" in buf.getvalue()  # both methods run, the figures are the third step


def test_methods_and_fit_print_units(tmp_path):
    res = _invoke("methods")
    text = " ".join(res.output.split())
    assert "q=0.0025 m²/step" in text and "v_max" in text and "units:" in text
    save([_recording()], tmp_path / "a.csv", format="csv")
    res = _invoke("fit", tmp_path / "a.csv")
    assert res.exit_code == 0 and "m²" in res.output


def test_fit_takes_units_and_refuses_keypoints(tmp_path):
    # the same recording written in millimetres, without its sidecar (read as metres
    # unless told): --units mm gives the metre recording's fit
    rec = _recording()
    save([rec], tmp_path / "m.csv", format="csv")
    save([rec.replace(positions=rec.positions * 1000.0, units="mm")], tmp_path / "mm.csv",
         format="csv")  # fmt: skip
    for side in tmp_path.glob("mm*.json"):
        side.unlink()
    runs = [_invoke("fit", tmp_path / "m.csv", "--json"),
            _invoke("fit", tmp_path / "mm.csv", "--units", "mm", "--json")]  # fmt: skip
    assert all(r.exit_code == 0 for r in runs), [r.output for r in runs]
    q_m, q_mm = (next(iter(json.loads(r.output).values()))["Q"] for r in runs)
    np.testing.assert_allclose(q_mm, q_m, rtol=1e-3)  # the CSVs' digits; a wrong unit: 1e6
    # 2-D keypoints: refused with the reason and what to use instead
    (tmp_path / "px.csv").write_text("time,Head_x,Head_y\n0.0,10,20\n0.033,11,21\n")
    res = _invoke("fit", tmp_path / "px.csv")
    _clean_failure(res, "2-D keypoints")
    assert "tobitkf smooth" in " ".join(res.output.split())


# --------------------------------------------------------------------------- point 11
def test_format_option_for_every_input_command(tmp_path):
    odd = tmp_path / "recording.txt"  # CSV content under a name no sniffer takes as CSV
    odd.write_text("time,Head_x,Head_y,Head_q\n0,1,2,3\n")
    good = tmp_path / "good.dat"
    save([_recording()], tmp_path / "good.csv", format="csv")
    shutil.copy(tmp_path / "good.csv", good)
    for args in (
        ["evaluate", odd, "--format", "csv"],
        ["report", odd, "--format", "csv", "-o", tmp_path / "r.html"],
        ["fit", odd, "--format", "csv"],
        ["smooth", odd, "-F", "csv", "-o", tmp_path / "out"],
    ):
        res = _invoke(*args)
        assert res.exit_code == 1, (args, res.output)
        assert "expected columns" in res.output, (args, res.output)
    res = _invoke("evaluate", good, "--format", "csv", "--methods", "raw")
    assert res.exit_code == 0, res.output
    res = _invoke("evaluate", odd, "--format", "nosuch")
    _clean_failure(res, "nosuch", status=2)


# --------------------------------------------------------------------------- point 12
def _small_report(tmp_path: Path) -> Path:
    from tobitkf.app.report import track_report

    seq = _recording(T=90)
    truth = np.asarray(seq.positions).copy()
    truth[30] = truth[29]  # the hand spike at frame 30 is a glitch against the truth
    path, _ = track_report(
        seq, tmp_path / "r.html", truth=truth, methods=["raw", "atkf", "robust"], gif=True
    )
    return path


def test_report_html_reads_well(tmp_path):
    page = _small_report(tmp_path).read_text()
    assert "<td>None</td>" not in page and ">None<" not in page
    # every table sits in a container that scrolls sideways instead of running off the page
    assert page.count("<table>") == page.count("<div class='table-scroll'><table>") >= 1
    assert ".table-scroll{overflow-x:auto" in page
    # captions say what a figure shows, not its file name
    captions = [c.split("</figcaption>")[0] for c in page.split("<figcaption class='note'>")[1:]]
    assert len(captions) >= 3
    assert not any(c.endswith((".png", ".gif")) for c in captions)
    assert any("Shaded" in c for c in captions) and any("every frame" in c for c in captions)
    # robust rejects samples: its rejected % is shown; raw has no clipping: "–"
    assert "rejected (%)" in page and "clipped (%)" in page
    row = page.split("<tr><td>robust</td>")[1].split("</tr>")[0]
    cells = [c.split("</td>")[0] for c in row.split("<td>")[1:]]
    assert cells[-2] == "–" and float(cells[-1]) > 0
    raw_row = page.split("<tr><td>raw</td>")[1].split("</tr>")[0]
    assert raw_row.count("<td>–</td>") >= 2


def test_gif_window_draws_every_frame(tmp_path):
    pytest.importorskip("matplotlib")
    from PIL import Image

    from tobitkf.app import plots

    pos = np.zeros((400, 3, 3))
    pos[:, 1, 1] = 1.0
    pos[:, 2, 1] = 2.0
    pos[201, 2] += 0.5  # a one-frame spike
    out = plots.animate_skeletons({"raw": pos}, [-1, 0, 1], tmp_path / "a.gif", window=(150, 250))
    with Image.open(out) as im:
        assert im.n_frames == 100  # every frame of the window, the spike's included


def _traces_spy(monkeypatch) -> list[dict]:
    """Every call of plot_joint_traces and plot_skeleton_frames: kwargs and the figure."""
    from tobitkf.app import plots

    calls: list[dict] = []
    for name in ("plot_joint_traces", "plot_skeleton_frames"):
        original = getattr(plots, name)

        def spy(*args, _original=original, _name=name, **kwargs):
            fig = _original(*args, **kwargs)
            calls.append({"name": _name, "args": args, "kwargs": kwargs, "fig": fig})
            return fig

        monkeypatch.setattr(plots, name, spy)
    return calls


def test_report_of_2d_image_keypoints_in_pixels(tmp_path, monkeypatch):
    from tobitkf.app.report import track_report

    pytest.importorskip("matplotlib")
    seq = _recording(T=60)
    px = 400.0 * np.asarray(seq.positions)[..., :2]  # x, y in pixels
    px[..., 1] *= -1  # image y points down
    seq2d = seq.replace(positions=px, units="px")
    calls = _traces_spy(monkeypatch)
    path, _ = track_report(seq2d, tmp_path / "r.html", methods=["raw", "kf", "robust"])
    page = path.read_text()
    # lengths in the recording's own unit, not converted to cm or m²
    assert "M (px²)" in page and "largest jump (px)" in page
    assert "(cm)" not in page and "1e-3 m²" not in page
    traces = [c for c in calls if c["name"] == "plot_joint_traces"]
    assert traces
    for c in traces:
        axes = c["fig"].axes
        assert len(axes) == 2  # x and y: no z panel
        assert [a.get_ylabel() for a in axes] == ["x [px]", "y [px], down"]
        assert axes[1].yaxis_inverted() and not axes[0].yaxis_inverted()
    (skel,) = [c for c in calls if c["name"] == "plot_skeleton_frames"]
    assert all(ax.yaxis_inverted() for ax in skel["fig"].axes)  # as in the image
    assert "x and y (pointing down, as in the image)" in page
    assert "Skeletons as in the image" in page
    # the 10 cm threshold has no meaning in pixels: a share of the body's height instead
    assert "px (6 % of the body&#x27;s height)" in page and "10 cm" not in page


def test_report_command_runs_on_pixels_without_the_methods_in_metres(tmp_path):
    seq = _recording(T=60)
    px = 400.0 * np.asarray(seq.positions)[..., :2]
    save([seq.replace(positions=px, units="px")], tmp_path / "k.csv", format="csv")
    res = _invoke("report", tmp_path / "k.csv", "-o", tmp_path / "r.html", "--no-gif")
    assert res.exit_code == 0, res.output
    out = " ".join(res.output.split())
    assert "Left out: atkf, atkf2016" in out and "in px" in out
    page = (tmp_path / "r.html").read_text()
    assert "Left out: atkf, atkf2016" in page
    assert "<tr><td>robust</td>" in page and "<tr><td>atkf</td>" not in page


@pytest.mark.parametrize("folder", ["new/", "existing"])
def test_report_into_a_folder_writes_report_html_in_it(tmp_path, folder):
    # "-o reports/" named a file "reports"; an existing folder was refused
    seq = _recording(T=40)
    save([seq], tmp_path / "k.csv", format="csv")
    (tmp_path / "existing").mkdir()
    target = f"{tmp_path}/{folder}"
    res = _invoke("report", tmp_path / "k.csv", "-o", target, "--no-gif", "--methods", "raw,kf")
    assert res.exit_code == 0, res.output
    assert (tmp_path / folder.rstrip("/") / "report.html").is_file()


@pytest.mark.parametrize(
    ("units", "methods"),
    [("m", ["raw", "kf", "robust"]), ("mm", ["raw", "kf", "robust"]), ("m", ["raw", "kf"])],
)
def test_report_shades_a_sustained_glitch_without_truth(tmp_path, monkeypatch, units, methods):
    """Without truth the raw track is held against robust, not a filter that follows the
    glitch: the 30 frames a hand sits 40 cm off are the frames shaded, in metres or in
    millimetres (10 cm = 100 mm, axes labelled in the track's unit), and also when robust
    is not among the methods shown (it is run for the shading, and the caption says so)."""
    from tobitkf.app.report import track_report

    pytest.importorskip("matplotlib")
    seq = _recording(T=120)
    pos = np.asarray(seq.positions).copy()
    hand = seq.topology.index("HandLeft")
    pos[50:80, hand, 1] += 0.4
    scale = {"m": 1.0, "mm": 1000.0}[units]
    calls = _traces_spy(monkeypatch)
    track_report(
        seq.replace(positions=scale * pos, units=units),
        tmp_path / "r.html",
        methods=methods,
        gif=False,
    )
    traces = {c["kwargs"]["title"]: c for c in calls if c["name"] == "plot_joint_traces"}
    assert traces["HandLeft"]["kwargs"]["shade"] == [(50, 80)]
    assert traces["HandLeft"]["fig"].axes[0].get_ylabel() == f"x [{units}]"
    assert ("robust" in traces["HandLeft"]["args"][1]) == ("robust" in methods)  # drawn?
    drawn = "" if "robust" in methods else " (not drawn)"
    assert f"from the robust output{drawn}." in (tmp_path / "r.html").read_text()


def test_report_does_not_claim_glitches_where_there_are_none(tmp_path, monkeypatch):
    from tobitkf.app.report import track_report

    seq = _recording(T=60)
    calls = _traces_spy(monkeypatch)
    path, _ = track_report(seq, tmp_path / "r.html", truth=seq.positions, methods=["raw", "kf"])
    page = path.read_text()
    assert "Shaded red" not in page and "most such frames" not in page
    assert "nothing shaded" in page and "largest one-frame jumps" in page
    assert "worst glitch" not in page and "no glitch: never more than 10 cm" in page
    # Kinect camera space: y up, x to the sensor's left (a mirror view, not "the front")
    assert "Skeletons in the recording&#x27;s x-y plane (x to the right, y up)" in page
    (skel,) = [c for c in calls if c["name"] == "plot_skeleton_frames"]
    assert skel["kwargs"]["title"] == "skeletons where raw is furthest from the truth"


def _screenshot(page: Path, tmp_path: Path, width: int, height: int) -> np.ndarray:
    """The page as headless Chromium draws it in a window of ``width`` × ``height`` px,
    in grey levels."""
    from PIL import Image

    shot = tmp_path / f"shot{width}.png"
    subprocess.run(
        [
            "chromium",
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--no-first-run",
            "--hide-scrollbars",
            f"--user-data-dir={tmp_path / 'profile'}",
            f"--window-size={width},{height}",
            f"--screenshot={shot}",
            page.resolve().as_uri(),
        ],
        check=True,
        capture_output=True,
        timeout=120,
    )
    with Image.open(shot) as im:
        assert im.size == (width, height)
        return np.asarray(im.convert("L"), dtype=float)


@pytest.mark.skipif(shutil.which("chromium") is None, reason="chromium is not installed")
def test_report_renders_in_chromium(tmp_path):
    grey = _screenshot(_small_report(tmp_path), tmp_path, 1400, 2400)
    assert grey.std() > 10  # a page with tables and figures, not a blank or error page
    # nothing runs off to the right: the rightmost 40 px are page background
    assert (grey[:, -40:-20] > 240).mean() > 0.99


@pytest.mark.skipif(shutil.which("chromium") is None, reason="chromium is not installed")
def test_report_fits_a_phone_screen_even_with_a_long_file_name(tmp_path):
    from tobitkf.app.report import track_report

    name = "G3_Kinect_ELK_P1T1_Unknown_C_0_" * 3 + ".txt"  # one long word, no hyphen
    seq = _recording(T=60)
    seq = seq.replace(metadata={**seq.metadata, "source": f"/home/someone/private/{name}"})
    page, _ = track_report(seq, tmp_path / "r.html", methods=["raw", "kf"], gif=False)
    text = page.read_text()
    # the file's name, not the folders it sits in (the page is mailed to others)
    assert f"<h1>tobitkf report: {name}</h1>" in text and "/home/someone" not in text
    assert "name='viewport' content='width=device-width" in text
    # a file of several bodies: the title says which one the page shows
    page2, _ = track_report(
        seq.replace(body_id="person1"), tmp_path / "r2.html", methods=["raw"], gif=False
    )
    assert f"<h1>tobitkf report: {name} (body person1)</h1>" in page2.read_text()
    grey = _screenshot(page, tmp_path, 420, 1600)
    assert grey[:300].std() > 10  # the title is drawn
    # the title wraps inside the window: the rightmost 12 px are page background
    assert grey[:, -12:].min() > 230


def test_smooth_says_a_methods_warning_once_per_file_in_plain_words(tmp_path):
    # tkfc with the Kinect's device limits on a recording whose feet sit below them
    seq = _recording()
    pos = seq.positions.copy()
    pos[:, [15, 19], 1] = -1.55  # FootLeft, FootRight
    save([seq.replace(positions=pos)], tmp_path / "low.csv", format="csv")
    res = _invoke("smooth", tmp_path / "low.csv", "--method", "tkfc", "-o", tmp_path / "out")
    assert res.exit_code == 0, res.output
    out = " ".join(res.output.split())
    assert out.count("beyond the censoring limits") == 1
    assert "warning" in out and "low.csv" in out
    assert "UserWarning" not in res.output


def test_report_of_the_raw_track_alone_says_so(tmp_path, monkeypatch):
    from tobitkf.app.report import track_report

    calls = _traces_spy(monkeypatch)
    path, _ = track_report(_recording(T=60), tmp_path / "r.html", methods=["raw"])
    page = path.read_text()
    assert "furthest from ;" not in page and "against ." not in page
    assert "the raw track alone (no method or truth to compare it with)" in page
    # the snapshots sit around the one-frame hand spike at frame 30 (_recording)
    assert "around frame 30, where a raw sample is furthest from its neighbouring" in page
    (skel,) = [c for c in calls if c["name"] == "plot_skeleton_frames"]
    assert skel["args"][1] == [20, 30, 40]


def test_report_warnings_stand_out_from_the_notes():
    from tobitkf.app.report import ReportInput, render_html

    notes = ["Warning: time alignment is doubtful.", "Left out: atkf."]
    page = render_html(ReportInput("t", _recording(T=40), {}, notes=notes), {})
    assert "<p class='warning'>Warning: time alignment is doubtful.</p>" in page
    assert "<p>Left out: atkf.</p>" in page and ".warning{border-left" in page


@pytest.mark.parametrize("command", ["report", "evaluate"])
def test_a_narrow_terminal_gets_a_summary_not_wrapped_lines(tmp_path, monkeypatch, command):
    from tobitkf.app.commands import _common
    from tobitkf.app.commands import evaluate as evaluate_command

    seq = _recording(T=60)
    save([seq], tmp_path / "a.csv", format="csv")
    save([seq], tmp_path / "truth.csv", format="csv")
    pairs = tmp_path / "pairs.csv"
    pairs.write_text("".join(f"{j},{j}\n" for j in seq.joint_names))
    for width, terminal in ((50, True), (250, True), (50, False)):
        buf = io.StringIO()
        console = Console(file=buf, width=width, force_terminal=terminal)
        monkeypatch.setattr(_common, "console", console)
        monkeypatch.setattr(evaluate_command, "console", console)
        args = [command, tmp_path / "a.csv", "-t", tmp_path / "truth.csv", "--pairs", pairs]
        if command == "report":
            args += ["-o", tmp_path / "r.html", "--no-gif"]
        res = _invoke(*args, "--methods", "raw,kf")
        assert res.exit_code == 0, res.output
        out = Text.from_ansi(buf.getvalue()).plain
        assert command == "evaluate" or "report written to" in out
        if width == 50 and terminal:  # every line fits; each method's RMSE on its own line
            # (evaluate's rule names the files: a path may be longer than the terminal)
            lines = [ln for ln in out.splitlines() if str(tmp_path) not in ln and "──" not in ln]
            assert max(len(line) for line in lines) <= width
            assert out.count("RMSE (cm): ") == 2 and "method: kf" in out
        else:  # wide enough, or a pipe / log file: the whole table, as evaluate prints it
            assert "hands" in out and "sust." in out


def test_a_narrow_terminal_gets_whole_words_not_squeezed_columns(monkeypatch):
    from tobitkf.app.commands import _common

    columns = ["file", "bodies", "% clipped/rejected", "seconds"]
    rows = [["JointPositionExercise3.csv", 1, 7.594, 0.09], ["b.csv", 2, float("nan"), 1.5]]
    for width, blocks in ((50, True), (200, False)):
        buf = io.StringIO()
        monkeypatch.setattr(_common, "console", Console(file=buf, width=width))
        _common._print_table("tobitkf smooth", columns, rows)
        out = buf.getvalue()
        assert max(len(line) for line in out.splitlines()) <= width
        # every header and file name whole, on a line of its own or in its column
        for word in ("JointPositionExercise3.csv", "% clipped/rejected", "7.59", "1.50"):
            assert word in out
        assert ("file: JointPositionExercise3.csv" in out) == blocks
        assert ("% clipped/rejected: -" in out) == blocks  # NaN shown as "-"
    # a name that folds to a few lines is still a table (only the names fold)
    buf = io.StringIO()
    monkeypatch.setattr(_common, "console", Console(file=buf, width=70))
    _common._print_table("t", columns, [["x" * 40, 1, 2.0, 3.0]])
    out = buf.getvalue()
    assert "file:" not in out and "x" * 40 not in out and "x" * 18 in out
    assert "% clipped/rejected" in out and max(len(line) for line in out.splitlines()) <= 70


def _commands(group, prefix=()):
    for name, cmd in sorted(group.commands.items()):
        if isinstance(cmd, click.Group):
            yield from _commands(cmd, (*prefix, name))
        else:
            yield (*prefix, name)


@pytest.mark.parametrize("command", list(_commands(app)), ids=" ".join)
def test_help_fits_a_narrow_terminal(command):
    """Every command's help at 50 columns: no line wider (a choice list as click's
    ``[a|b|c]`` metavar was one unbroken line of 200 characters), and the short help of
    each subcommand is more than its first abbreviation ("Eq.")."""
    res = CliRunner().invoke(app, [*command, "--help"], terminal_width=50)
    assert res.exit_code == 0, res.output
    wide = [line for line in res.output.splitlines() if len(line) > 50]
    assert not wide, wide
    if command == ("evaluate",):  # a list wraps between its names, not inside them
        assert all(f"{name}," in res.output for name in ("atkf2016", "one_euro", "kf+rts"))
    cmd = app
    for part in command:
        cmd = cmd.get_command(None, part)
    assert len(cmd.get_short_help_str(limit=200)) > 12


def test_columns_is_obeyed_when_piped():
    """Piped output gets whole tables (160 columns) unless COLUMNS says otherwise."""
    env = {**os.environ, "COLUMNS": "50"}
    out = subprocess.run([sys.executable, "-m", "tobitkf", "methods"], env=env,
                         capture_output=True, text=True, check=True).stdout  # fmt: skip
    assert max(len(line) for line in out.splitlines()) <= 50
    env.pop("COLUMNS")
    out = subprocess.run([sys.executable, "-m", "tobitkf", "methods"], env=env,
                         capture_output=True, text=True, check=True).stdout  # fmt: skip
    assert max(len(line) for line in out.splitlines()) > 100


def test_messages_keep_a_long_path_on_one_line_in_a_narrow_pipe(tmp_path):
    """A warning or failure names its file whole, however narrow the output: a path cut
    in two is neither found by grep in a log nor copied from a terminal."""
    import numpy as np

    deep = tmp_path / "a_rather_long_folder_name" / "and_another_long_level_below_it"
    deep.mkdir(parents=True)
    arr = np.cumsum(np.random.default_rng(0).normal(0, 0.01, (20, 4, 3)), axis=0)
    np.save(deep / "a_long_recording_name_of_its_own.npy", arr)  # warns: no rate, no bones
    (deep / "broken_recording_with_a_long_name.trc").write_text("not a trc file\n")
    env = {**os.environ, "COLUMNS": "50"}
    run = subprocess.run(
        [sys.executable, "-m", "tobitkf", "smooth", str(deep), "-o", str(tmp_path / "o")],
        env=env, capture_output=True, text=True, check=False,
    )  # fmt: skip
    lines = run.stderr.splitlines()
    for name in ("a_long_recording_name_of_its_own.npy", "broken_recording_with_a_long_name.trc"):
        path = str(deep / name)
        assert any(path in line for line in lines), run.stderr
    assert any(line.startswith("warning") and "no frame rate" in line for line in lines)


def test_piped_tables_have_no_trailing_spaces(tmp_path):
    """A title line padded to the table's width leaves trailing spaces in every log."""
    import numpy as np

    np.save(tmp_path / "a.npy", np.cumsum(np.ones((20, 4, 3)), axis=0))
    env = {**os.environ, "COLUMNS": "200"}  # a table, not the narrow blocks
    out = subprocess.run(
        [sys.executable, "-m", "tobitkf", "smooth", str(tmp_path / "a.npy"), "-o",
         str(tmp_path / "o")], capture_output=True, text=True, check=True, env=env,
    ).stdout  # fmt: skip
    assert "tobitkf smooth" in out and "│ a.npy" in out
    assert not [line for line in out.splitlines() if line.endswith(" ")]


def test_evaluate_on_pixels_leaves_out_the_methods_in_metres(tmp_path):
    """Without --methods, evaluate on image keypoints ran atkf with half-widths in metres
    and stopped; it leaves atkf and atkf2016 out and says so, as report does."""
    import numpy as np

    import tobitkf as tk

    rng = np.random.default_rng(0)
    kp = rng.uniform(200, 600, (17, 2))[None] + np.cumsum(rng.normal(0, 1, (60, 17, 2)), 0)
    seq = tk.SkeletonSequence(kp, tk.get_topology("coco17"), fps=30.0, units="px")
    tk.save([seq], tmp_path / "px.csv")
    run = subprocess.run([sys.executable, "-m", "tobitkf", "evaluate", str(tmp_path / "px.csv")],
                         capture_output=True, text=True, check=False)  # fmt: skip
    assert run.returncode == 0, run.stderr
    assert "Left out: atkf, atkf2016" in " ".join(run.stderr.split())
    assert "robust_online" in run.stdout and " atkf " not in run.stdout


def test_columns_is_read_at_each_invocation_not_at_import():
    """rich reads COLUMNS when a console is made; the CLI's table console is made at
    import, so a second in-process ``main()`` (a notebook, a test) kept the first width."""
    from click.testing import CliRunner

    from tobitkf.app.commands import app

    for columns, widest in (("50", lambda n: n <= 50), ("300", lambda n: n > 100)):
        out = CliRunner(env={"COLUMNS": columns}).invoke(app, ["methods"]).output
        assert widest(max(len(line) for line in out.splitlines())), (columns, out)
    out = CliRunner(env={"COLUMNS": None}).invoke(app, ["methods"]).output  # a pipe
    assert max(len(line) for line in out.splitlines()) > 300  # not cut at 50 or 300
    assert commands.console.width == 160  # tables fit in 160 columns in a pipe


def test_piped_lines_are_not_wrapped_in_the_middle_of_a_parameter():
    """Piped (no terminal, no COLUMNS), ``methods`` cut its lines at 160 characters, in
    the middle of robust's ``speed_sd={'hands': 1.0, 'arms': ...}``: a line is whole."""
    from tobitkf.smoothing.api import methods

    env = {k: v for k, v in os.environ.items() if k != "COLUMNS"}
    out = subprocess.run([sys.executable, "-m", "tobitkf", "methods"], env=env,
                         capture_output=True, text=True, check=True).stdout  # fmt: skip
    lines = out.splitlines()
    for name, spec in methods().items():
        wanted = [f"{k}=" for k in spec.defaults]
        assert any(all(w in line for w in wanted) for line in lines), (name, wanted, out)
    assert any(len(line) > 160 for line in lines)  # robust's: longer than the width


def test_method_labels_with_parameters_are_shown_whole(tmp_path):
    """atkf[c=0.1] and atkf[c=0.3] are two rows, not two 'atkf' (rich markup)."""
    track, truth = tmp_path / "a.csv", tmp_path / "truth.csv"
    rec = _recording()
    save([rec], track, format="csv")
    save([rec.replace(positions=rec.positions + 0.01)], truth, format="csv")
    methods = "raw,atkf[c=0.1],atkf[c=0.3]"
    two = [track, track, "--truth", truth, "--truth", truth]
    # a row per table: without truth one, with it the scores and the angles, and with
    # two recordings the pooled table (a rich table) too
    for args, tables in (
        (["evaluate", track], 1),
        (["evaluate", track, "--truth", truth], 2),
        (["evaluate", *two], 5),
    ):
        res = CliRunner(env={"COLUMNS": "250"}).invoke(app, [*map(str, args), "--methods", methods])
        assert res.exit_code == 0, res.output
        for label in ("atkf[c=0.1]", "atkf[c=0.3]"):
            assert res.output.count(label) == tables, res.output


def test_evaluate_says_what_is_wrong_with_its_options(tmp_path):
    track = tmp_path / "a-Kinect-.csv"
    save([_recording()], track, format="csv")
    res = _invoke("evaluate", track, "--truth-replace", "-kinect-", "-Vicon-")
    assert res.exit_code != 0 and "'-kinect-' is not in the path" in res.output
    for command in (["evaluate", track], ["benchmark", "--duration", "1"]):
        res = _invoke(*command, "--json", "--markdown")
        assert res.exit_code != 0 and "give --json or --markdown, not both" in res.output


def test_the_pose2d_benchmark_table_says_nothing_scored_as_the_markdown_does():
    """Labels with no sample (raw's missing keypoints) are "–", not "nan ± nan"; one seed
    has no spread to show."""
    args = ["benchmark", "--kind", "pose2d", "--duration", "2", "--methods", "raw"]
    res = CliRunner(env={"COLUMNS": "200"}).invoke(app, args)
    md = CliRunner().invoke(app, [*args, "--markdown"])
    assert res.exit_code == 0 and md.exit_code == 0, res.output
    assert "nan" not in res.output and "±" not in res.output
    assert "–" in md.output and "–" in res.output


@pytest.mark.parametrize("name", ["out.c3d", "res.csv", "nested/clean.trc"])
def test_an_outdir_named_like_a_file_is_a_usage_error(tmp_path, name):
    # "-o out.c3d" made a folder out.c3d holding a.robust.csv
    seq = _recording(T=40)
    save([seq], tmp_path / "a.csv", format="csv")
    res = _invoke("smooth", tmp_path / "a.csv", "-o", tmp_path / name, "-m", "kf")
    assert res.exit_code == 2, res.output
    text = " ".join(res.output.split())
    ext = name.rsplit(".", 1)[1]
    assert "looks like a file name" in text and f"-f {ext}" in text
    assert not (tmp_path / name).exists()
    # an existing folder of that name is a folder
    (tmp_path / name).mkdir(parents=True)
    res = _invoke("smooth", tmp_path / "a.csv", "-o", tmp_path / name, "-m", "kf")
    assert res.exit_code == 0, res.output
    assert (tmp_path / name / "a.kf.csv").is_file()
    # a new folder said to be one (a trailing /) is a folder too
    res = _invoke("smooth", tmp_path / "a.csv", "-o", f"{tmp_path}/new.{ext}/", "-m", "kf")
    assert res.exit_code == 0, res.output
    assert (tmp_path / f"new.{ext}" / "a.kf.csv").is_file()


def test_a_missing_writer_package_fails_once_before_any_file(tmp_path, monkeypatch):
    # each file failed with "reading C3D files needs ..." after being read and smoothed,
    # and the output folder and a manifest were made
    import sys

    seq = _recording(T=40)
    for name in ("a", "b"):
        save([seq], tmp_path / f"{name}.csv", format="csv")
    monkeypatch.setitem(sys.modules, "c3d", None)
    out = tmp_path / "out"
    res = _invoke("smooth", tmp_path / "a.csv", tmp_path / "b.csv", "-o", out, "-f", "c3d")
    assert res.exit_code == 1, res.output
    text = " ".join(res.output.split())
    assert text.count("writing C3D files needs the 'c3d' package") == 1
    assert "pip install 'tobitkf[c3d]'" in text
    assert not out.exists()


def test_the_demo_without_matplotlib_writes_the_recordings_and_the_table(tmp_path, monkeypatch):
    # with the cli extra alone the demo stopped at "needs matplotlib": the recordings and
    # the table need no figure
    import sys

    monkeypatch.setitem(sys.modules, "matplotlib", None)
    res = _invoke("demo", "-o", tmp_path / "d", "--no-gif")
    assert res.exit_code == 0, res.output
    text = " ".join(res.output.split())
    assert "pip install 'tobitkf[plot]'" in text and "robust" in text
    assert (tmp_path / "d" / "synthetic_kinect.robust.csv").is_file()
    assert not (tmp_path / "d" / "report.html").exists()

"""The command-line tool, driven through click's runner (the CLI only parses and calls)."""

from __future__ import annotations

import base64
import json
import re

import numpy as np
import pytest

click = pytest.importorskip("click")
from click.testing import CliRunner  # noqa: E402

from conftest import data_file  # noqa: E402
from tobitkf.app.commands import app  # noqa: E402
from tobitkf.io import load, save  # noqa: E402
from tobitkf.skeleton.sequence import SkeletonSequence  # noqa: E402
from tobitkf.skeleton.topology import get_topology  # noqa: E402
from tobitkf.smoothing.api import smooth as smooth_api  # noqa: E402


def _run(*args: str) -> click.testing.Result:
    return CliRunner().invoke(app, list(args), catch_exceptions=False)


def _recording(T: int = 60, seed: int = 0) -> SkeletonSequence:
    """A still Kinect V2 body with 1 cm jitter and one 0.6 m one-frame hand spike."""
    rng = np.random.default_rng(seed)
    topo = get_topology("kinect_v2")
    n = len(topo.joints)
    base = rng.uniform(-0.5, 0.5, size=(n, 3)) + np.array([0.0, 0.0, 2.5])
    pos = base + rng.normal(scale=0.01, size=(T, n, 3))
    pos[30, topo.index("HandRight")] += [0.6, 0.0, 0.0]
    return SkeletonSequence(positions=pos, topology=topo, fps=30.0)


def test_smooth_folder_writes_outputs_atomically_and_reports_bad_files(tmp_path):
    src = tmp_path / "in"
    (src / "sub").mkdir(parents=True)
    save([_recording()], src / "a.csv", format="csv")
    save([_recording(seed=1)], src / "sub" / "b.csv", format="csv")
    (src / "broken.csv").write_text("time,Head_x\n0.0,abc\n")
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["smooth", str(src), "-o", str(out), "--glob", "*.csv"])
    assert res.exit_code == 1, res.output  # one bad file -> non-zero status
    assert "broken.csv" in res.output
    produced = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    # each output with its sidecar, the run's manifest, no temporary files left behind
    # the default method is robust
    assert produced == [
        "a.robust.csv",
        "a.robust.json",
        "sub/b.robust.csv",
        "sub/b.robust.json",
        "tobitkf-manifest.jsonl",
    ]
    # the spike is removed: the output's largest hand jump is far below the input's 0.6 m
    hand = get_topology("kinect_v2").index("HandRight")
    smoothed = load(out / "a.robust.csv")[0].positions[:, hand]
    raw = load(src / "a.csv")[0].positions[:, hand]
    jump = lambda p: np.nanmax(np.linalg.norm(np.diff(p, axis=0), axis=-1))  # noqa: E731
    assert jump(raw) > 0.55 and jump(smoothed) < 0.5 * jump(raw)


def test_smooth_never_overwrites_and_rejects_unknown_parameters(tmp_path):
    save([_recording()], tmp_path / "a.csv", format="csv")
    before = (tmp_path / "a.csv").read_bytes()
    res = _run("smooth", str(tmp_path / "a.csv"), "-o", str(tmp_path), "-m", "kf")
    assert res.exit_code == 0
    assert (tmp_path / "a.csv").read_bytes() == before
    assert (tmp_path / "a.kf.csv").exists()
    res = CliRunner().invoke(app, ["smooth", str(tmp_path / "a.csv"), "-p", "bogus=1"])
    assert res.exit_code == 2 and "bogus" in res.output
    res = CliRunner().invoke(app, ["smooth", str(tmp_path / "a.csv"), "-m", "nope"])
    # a usage error that names the registered methods
    assert res.exit_code == 2 and "'nope'" in res.output and "robust_online" in res.output
    for flag in (["--offline"], ["-p", "offline=true"]):
        res = CliRunner().invoke(app, ["smooth", str(tmp_path / "a.csv"), "-m", "sgf", *flag])
        assert res.exit_code == 2 and "does not have" in " ".join(res.output.split())


@pytest.mark.parametrize("fmt", ["c3d", "csv", "deeplabcut", "lightningpose", "mmpose",
                                 "movement", "npz", "ntu", "trc"])  # fmt: skip
def test_every_writable_format_is_an_output_a_rerun_knows(fmt, tmp_path):
    """``-f FORMAT`` writes the smoothed positions in that format; a second run, with
    the manifest gone, knows the file as its own output and redoes it instead of
    failing on a file it may not replace. (LightningPose shares ``.csv`` with the
    generic CSV, and once had no output name at all.)"""
    from tobitkf.io import output_extension, writable_formats

    if fmt not in writable_formats():  # an optional extra missing (movement: xarray)
        pytest.skip(f"{fmt} cannot be written here")
    src = tmp_path / "a.csv"
    save([_recording()], src, format="csv")
    for _ in range(2):
        res = _run("smooth", str(src), "-o", str(tmp_path / "o"), "-f", fmt)
        assert res.exit_code == 0 and "FAILED" not in res.output, res.output
        (tmp_path / "o" / "tobitkf-manifest.jsonl").unlink()
    (back,) = load(tmp_path / "o" / f"a.robust{output_extension(fmt)}", format=fmt)
    want = smooth_api(load(src)[0])
    # every format keeps the positions to its own precision (C3D: float32, TRC: mm text)
    np.testing.assert_allclose(back.positions, want.positions, rtol=0, atol=1e-3)


def test_smooth_takes_a_value_per_body_region(tmp_path):
    """``-p v_max=hands:6`` changes the hands' bound only, recorded in the provenance."""
    save([_recording()], tmp_path / "a.csv", format="csv")
    res = _run("smooth", str(tmp_path / "a.csv"), "-o", str(tmp_path / "o"), "-p",
               "v_max=hands:6")  # fmt: skip
    assert res.exit_code == 0, res.output
    side = json.loads((tmp_path / "o" / "a.robust.json").read_text())
    used = np.asarray(side["provenance"]["params"]["v_max"])
    groups = get_topology("kinect_v2").joint_groups()
    assert np.all(used[groups["hands"]] == 6.0) and np.all(used[groups["legs"]] == 10.0)
    # two -p for one parameter's regions: both apply; one region twice: refused
    res = _run("smooth", str(tmp_path / "a.csv"), "-o", str(tmp_path / "q"), "-p",
               "v_max=hands:6", "-p", "v_max=arms:4")  # fmt: skip
    side = json.loads((tmp_path / "q" / "a.robust.json").read_text())
    used = np.asarray(side["provenance"]["params"]["v_max"])
    assert np.all(used[groups["hands"]] == 6.0) and np.all(used[groups["arms"]] == 4.0)
    res = CliRunner().invoke(
        app, ["smooth", str(tmp_path / "a.csv"), "-p", "v_max=hands:6,hands:7"]
    )
    assert res.exit_code == 2 and "twice" in res.output
    res = CliRunner().invoke(app, ["smooth", str(tmp_path / "a.csv"), "-o", str(tmp_path / "p"),
                                   "-p", "v_max=1,2,3"])  # fmt: skip
    assert res.exit_code == 1 and "got 3 values" in res.output and "one per joint" in res.output


def _no_rate(tmp_path):
    """A recording whose file states no frame rate (a generic CSV without a time column
    or sidecar), with three samples below the confidence threshold."""
    seq = _recording().replace(fps=None)
    conf = np.ones(seq.positions.shape[:2])
    conf[10, :3] = 0.05
    path = tmp_path / "norate.csv"
    save([seq.replace(confidence=conf)], path, format="csv", sidecar=False)
    return path


def test_smooth_says_when_it_assumes_a_frame_rate_and_takes_fps(tmp_path):
    path = _no_rate(tmp_path)
    res = _run("smooth", str(path), "-o", str(tmp_path / "a"), "--json")
    (row,) = json.loads(res.output)
    assert any("no frame rate" in w and "--fps" in w for w in row["warnings"])
    assert json.loads((tmp_path / "a" / "norate.robust.json").read_text())["fps"] is None
    # the samples below the confidence threshold count as missing, as the method saw them
    assert row["missing_percent"] == pytest.approx(100 * 3 / (60 * 25))
    res = _run("smooth", str(path), "-o", str(tmp_path / "a"), "--fps", "60", "--json")
    (row,) = json.loads(res.output)
    assert not row["warnings"] and not row["extra"].get("skipped")  # another rate: redone
    assert json.loads((tmp_path / "a" / "norate.robust.json").read_text())["fps"] == 60.0
    for bad in ("1e9", "nan", "inf", "0"):  # beyond the rates a reader takes back
        res = CliRunner().invoke(app, ["smooth", str(path), "--fps", bad])
        assert res.exit_code == 2 and "--fps" in res.output
    # info says the rate is unknown instead of a duration in frames
    info = json.loads(_run("info", str(path), "--json").output)["sequences"][0]
    assert info["fps"] is None and info["duration_s"] is None
    assert "no frame rate in the file" in _run("info", str(path)).output


def test_offline_for_a_method_offline_by_itself_says_so(tmp_path):
    save([_recording()], tmp_path / "a.csv", format="csv")
    res = CliRunner().invoke(app, ["smooth", str(tmp_path / "a.csv"), "--offline"])
    assert res.exit_code != 0 and "'robust' is offline already" in res.output
    # an earlier output passed over names the file a re-run with another method would write
    _run("smooth", str(tmp_path / "a.csv"), "-o", str(tmp_path))
    res = CliRunner().invoke(app, ["smooth", str(tmp_path), "-o", str(tmp_path / "k"), "-m", "kf"])
    assert "a.robust.kf.csv" in res.output


def test_files_of_one_name_are_told_apart(tmp_path):
    for sub in ("kinect", "vicon"):
        (tmp_path / "in" / sub).mkdir(parents=True)
        save([_recording()], tmp_path / "in" / sub / "m01.csv", format="csv")
    res = CliRunner(env={"COLUMNS": "200"}).invoke(
        app, ["smooth", str(tmp_path / "in"), "-o", str(tmp_path / "o")]
    )
    assert res.exit_code == 0 and "kinect/m01.csv" in res.output and "vicon/m01.csv" in res.output
    # named one by one, their outputs would collide: the second is refused, saying why
    files = [str(tmp_path / "in" / sub / "m01.csv") for sub in ("kinect", "vicon")]
    res = CliRunner().invoke(app, ["smooth", *files, "-o", str(tmp_path / "p")])
    assert res.exit_code == 1 and "give the folder they share" in res.output


def test_no_empty_table_when_every_file_fails(tmp_path):
    (tmp_path / "bad.csv").write_text("time,Head_x\n0.0,abc\n")
    res = CliRunner().invoke(app, ["smooth", str(tmp_path / "bad.csv"), "-o", str(tmp_path / "o")])
    assert res.exit_code == 1 and "FAILED" in res.output and "bodies" not in res.output


def test_smooth_json_summary_and_parallel_jobs(tmp_path):
    for i in range(3):
        save([_recording(seed=i)], tmp_path / f"r{i}.csv", format="csv")
    res = _run(
        "smooth", str(tmp_path), "-o", str(tmp_path / "o"), "-j", "2", "--json", "-m", "one_euro"
    )
    rows = json.loads(res.output)
    assert [r["ok"] for r in rows] == [True] * 3
    assert all(r["frames"] == 60 and r["joints"] == 25 for r in rows)


def test_info_reports_frames_and_largest_jump(tmp_path):
    save([_recording()], tmp_path / "a.csv", format="csv")
    res = _run("info", str(tmp_path / "a.csv"), "--json")
    info = json.loads(res.output)
    body = info["sequences"][0]
    assert body["frames"] == 60 and body["joints"] == 25
    top = body["jumps"][0]
    assert top["joint"] == "HandRight" and top["frame"] in (30, 31)
    assert top["largest_jump"] > 0.55 and body["units"] == "m"
    assert "jump (m)" in _run("info", str(tmp_path / "a.csv")).output
    px = SkeletonSequence(_recording().positions[..., :2] * 500, "kinect_v2", fps=30.0, units="px")
    save([px], tmp_path / "px.csv", format="csv")
    assert "jump (px)" in _run("info", str(tmp_path / "px.csv")).output


def test_reproduce_covariance_example_json_keys_and_paper_agreement():
    res = _run("reproduce", "covariance-example", "--samples", "20000", "--json")
    d = json.loads(res.output)
    assert {"exact", "standard_tkf", "monte_carlo", "monte_carlo_se", "paper"} <= set(d)
    # eq. 24 and eq. 25 as printed in the 2020 paper (4 decimals), transcribed here
    eq24 = [[0.4651, 0.6962, 0.5085], [0.6962, 4.7747, 1.9189], [0.5085, 1.9189, 1.4379]]
    eq25 = [[0.2724, 0.4719, 0.5151], [0.4719, 5.0000, 3.2744], [0.5151, 3.2744, 3.2002]]
    assert np.abs(np.array(d["exact"]) - eq24).max() <= 5e-5 + 1e-12
    assert np.abs(np.array(d["standard_tkf"]) - eq25).max() <= 5e-5 + 1e-12
    # Monte Carlo within 4 standard errors of the exact matrix
    z = np.abs(np.array(d["monte_carlo"]) - d["exact"]) / np.array(d["monte_carlo_se"])
    assert z.max() < 4


def test_reproduce_oscillator_json_keys():
    res = _run("reproduce", "oscillator", "--runs", "4", "--steps", "100", "--json")
    d = json.loads(res.output)
    text = json.dumps(d)
    for key in ("rmse_x1", "rmse_x2", "nci_abs", "nci_signed"):
        assert key in text


def _embedded_images(html: str) -> list[bytes]:
    return [base64.b64decode(b) for b in re.findall(r"src='data:image/\w+;base64,([^']+)'", html)]


def test_report_with_ground_truth_embeds_nonempty_figures(tmp_path):
    kinect = data_file("keraal/G3-Kinect-ELK-P1T1-Unknown-C-0.txt")
    vicon = data_file("keraal/G3-Vicon-ELK-P1T1-Unknown-C-0.txt")
    out = tmp_path / "report.html"
    res = _run(
        "report", str(kinect), "--truth", str(vicon), "-o", str(out), "--methods", "raw,atkf,kf+rts"
    )
    assert res.exit_code == 0
    html = out.read_text()
    images = _embedded_images(html)
    assert len(images) >= 5  # traces of 3 joints, skeleton snapshots, animation
    assert all(len(img) > 2000 for img in images)
    assert sum(img.startswith(b"GIF8") for img in images) == 1
    assert "Accuracy against ground truth" in html


def test_demo_runs_on_builtin_recording(tmp_path):
    res = _run("demo", "-o", str(tmp_path / "d"), "--no-gif")
    assert res.exit_code == 0
    assert "report:" in res.output
    assert (tmp_path / "d" / "report.html").stat().st_size > 10_000
    raw = load(tmp_path / "d" / "synthetic_kinect.csv")[0]
    assert raw.n_joints == 25 and raw.n_frames > 100


def test_report_shows_a_doubtful_time_alignment(tmp_path):
    # UI-PRMD m02 e01: the Vicon file covers about half of the Kinect recording
    path = "ui-prmd/Segmented Movements/{}/Positions/m02_s01_e01_positions.txt.gz"
    out = tmp_path / "report.html"
    res = _run(
        "report",
        str(data_file(path.format("Kinect"))),
        "--truth",
        str(data_file(path.format("Vicon"))),
        "-o",
        str(out),
        "--methods",
        "raw",
        "--no-gif",
    )
    assert res.exit_code == 0
    assert "covers only" in out.read_text()
    assert "covers only" in res.output


def test_bad_input_is_one_clear_error_with_a_nonzero_status(tmp_path):
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    junk = tmp_path / "junk.txt"
    junk.write_text("hello world\n")
    kinect = str(data_file("keraal/G3-Kinect-CTK-P1T1-Unknown-C-0.txt"))
    qtm = str(data_file("krajjat/test_sequence_qtm_2.tsv"))  # no joint name in common
    cases = [
        (["evaluate", str(tmp_path / "missing.csv")], 2, "does not exist"),
        (["evaluate", str(empty)], 1, "empty file"),
        (["evaluate", str(junk)], 1, "unrecognised content"),
        (["evaluate", kinect, "--truth", str(empty)], 1, "cannot read truth"),
        (
            ["evaluate", kinect, "--truth", qtm, "--methods", "raw"],
            1,
            "give a pairing table with --pairs",
        ),
        # an unknown method fails before any file is read
        (["evaluate", str(junk), "--methods", "raw,nosuch"], 2, "unknown method 'nosuch'"),
        (["report", str(junk), "--methods", "nosuch"], 2, "unknown method 'nosuch'"),
        (["fit", str(empty)], 1, "empty file"),
    ]
    for args, status, message in cases:
        res = CliRunner().invoke(app, args)
        assert res.exit_code == status, (args, res.output)
        assert message in res.output, (args, res.output)
        assert res.exception is None or isinstance(res.exception, SystemExit), args
        assert "Traceback" not in res.output, args


def test_info_says_what_the_reader_left_out():
    path = data_file("btkdata/PiG_Motion-FlatFoot-Full.c3d")
    said = load(path)[0].metadata["reader_warnings"]
    assert said  # the angles, forces, moments and powers of Plug-in Gait
    body = json.loads(_run("info", str(path), "--json").output)["sequences"][0]
    assert body["reader_warnings"] == list(said)
    out = CliRunner(env={"COLUMNS": "400"}).invoke(app, ["info", str(path)]).output
    assert all(note in out for note in said)


def test_evaluate_pairs_a_truth_in_the_tracks_own_skeleton_by_name(tmp_path):
    """A truth that names the track's joints (a simulation, a lifter's joints) is paired
    joint by joint without a table: 1 cm of white noise per axis is sqrt(3) cm of 3-D
    error, about what raw scores."""
    import json

    import numpy as np

    import tobitkf as tk

    truth = tk.generate_motion("walk", duration=4.0, seed=3)
    noisy = truth.replace(
        positions=truth.positions + np.random.default_rng(4).normal(0, 0.01, truth.positions.shape)
    )
    tk.save([truth], tmp_path / "truth.csv")
    tk.save([noisy], tmp_path / "track.csv")
    out = tmp_path / "res"
    res = CliRunner().invoke(app, ["evaluate", str(tmp_path / "track.csv"), "--truth",
                                   str(tmp_path / "truth.csv"), "--methods", "raw",
                                   "-o", str(out)])  # fmt: skip
    assert res.exit_code == 0, res.output
    (table,) = json.loads((out / "results.json").read_text()).values()
    (raw,) = [r for r in table["scores"] if r["method"] == "raw"]
    assert 1.5 < 100 * raw["rmse"] < 1.9  # metres
    assert len(table["paired_joints"]) == truth.n_joints


def test_the_individuals_of_a_file_are_smoothed_together(tmp_path):
    """Two animals in pixels whose identities the tracker swapped for a second: the CLI
    smooths a file's bodies in one call, as tk.smooth(list) does, so the swap is undone
    (each body smoothed alone keeps it)."""
    from tobitkf.skeleton.topology import Topology

    T, t = 150, np.arange(150)
    topo = Topology.from_names(["snout", "ear_l", "ear_r", "tail"], [-1, 0, 0, 0])
    true = np.zeros((T, 2, 4, 2))
    for k in range(2):
        for j in range(4):
            true[:, k, j] = np.c_[200 + 250 * k + 40 * np.sin(t / 15 + k) + 15 * j,
                                  200 + 40 * np.cos(t / 15 + k) + 5 * j]  # fmt: skip
    seen = true + np.random.default_rng(0).normal(0, 1, true.shape)
    seen[60:90] = seen[60:90, ::-1]  # the identities swapped
    seqs = [SkeletonSequence(seen[:, k], topo, fps=30.0, body_id=f"m{k}", units="px")
            for k in range(2)]  # fmt: skip
    save(seqs, tmp_path / "two.csv", format="csv")
    assert _run("smooth", str(tmp_path / "two.csv"), "-o", str(tmp_path / "out")).exit_code == 0
    out = load(tmp_path / "out" / "two.robust.csv")
    for a, b in zip(out, smooth_api(seqs), strict=True):
        np.testing.assert_array_equal(a.positions, b.positions)

    def rmse(results):
        est = np.stack([s.positions for s in results], 1)
        return float(np.sqrt(np.mean(np.sum((est - true) ** 2, -1))))

    assert rmse(out) < 2.0 < 10.0 < rmse([smooth_api(s) for s in seqs])


def test_a_data_set_gets_its_totals_not_a_row_per_file(tmp_path):
    """More files than MAX_TABLE_ROWS: one row of totals (checked against the JSON
    summary of the same run), the tally counts every file."""
    from tobitkf.app.commands.smooth import MAX_TABLE_ROWS
    from tobitkf.evaluation.ntu_like import write_ntu_like

    n = MAX_TABLE_ROWS + 2
    write_ntu_like(tmp_path / "in", n, frames=(20, 24))
    res = CliRunner(env={"COLUMNS": "200"}).invoke(
        app, ["smooth", str(tmp_path / "in"), "-o", str(tmp_path / "o"), "-m", "kf"]
    )
    assert res.exit_code == 0, res.output
    assert f"{n} files (every one in the manifest and --json)" in res.output
    assert "S001C001P001R001A001" not in res.output and f"{n} smoothed" in res.output
    again = CliRunner().invoke(
        app, ["smooth", str(tmp_path / "in"), "-o", str(tmp_path / "j"), "-m", "kf", "--json"]
    )
    summary = json.loads(again.output)
    frames, bodies = sum(r["frames"] for r in summary), sum(r["bodies"] for r in summary)
    row = next(ln for ln in res.output.splitlines() if f"{n} files" in ln)
    assert f" {bodies} " in row and f" {frames} " in row

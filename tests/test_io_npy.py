"""The plain ``.npy`` keypoint array reader, its sidecar, and the topologies it names."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from fuzzing import SETTINGS, check_reader
from tobitkf.io import ReadError, detect_format, load
from tobitkf.io.npy import read_npy
from tobitkf.skeleton.topology import get_topology


def _walk(T=40, J=17, D=3, seed=0):
    rng = np.random.default_rng(seed)
    return np.cumsum(rng.normal(0, 0.01, (T, J, D)), axis=0) + rng.normal(0, 0.3, (1, J, D))


def test_array_written_by_numpy_reads_back(tmp_path):
    arr = _walk()
    arr[3, 5] = np.nan  # a missing keypoint
    p = tmp_path / "poses.npy"
    np.save(p, arr.astype(np.float32))
    assert detect_format(p) == "npy"
    (seq,) = load(p)
    np.testing.assert_array_equal(seq.positions, arr.astype(np.float32).astype(float))
    assert seq.topology.joints == tuple(str(j) for j in range(17))
    assert seq.topology.bones == []  # nothing says which joint hangs from which
    assert seq.fps is None and seq.units is None  # an array states neither
    (note,) = seq.metadata["reader_warnings"]
    assert "poses.json" in note and "topology" in note


def test_content_not_the_name_decides(tmp_path):
    p = tmp_path / "keypoints.dat"
    np.save(p.with_suffix(".npy"), _walk(J=5))
    p.with_suffix(".npy").rename(p)
    assert detect_format(p) == "npy"


def test_several_bodies_and_image_keypoints(tmp_path):
    arr = _walk(T=12, J=17 * 2, D=2).reshape(12, 2, 17, 2) * 100
    p = tmp_path / "two.npy"
    np.save(p, arr)
    seqs = read_npy(p, topology="coco")
    assert [s.body_id for s in seqs] == [0, 1]
    for b, s in enumerate(seqs):
        np.testing.assert_array_equal(s.positions, arr[:, b])
        assert s.topology is get_topology("coco17") and s.n_dims == 2
        assert "reader_warnings" not in s.metadata


def test_sidecar_names_skeleton_rate_and_units_arguments_win(tmp_path):
    p = tmp_path / "lifted.npy"
    np.save(p, _walk())
    (tmp_path / "lifted.json").write_text(json.dumps({"topology": "h36m", "fps": 50, "units": "m"}))
    (seq,) = load(p)
    assert seq.topology.name == "h36m17" and seq.fps == 50.0 and seq.units == "m"
    (seq,) = load(p, fps=25, units="mm", topology="coco17")
    assert seq.topology.name == "coco17" and seq.fps == 25.0 and seq.units == "mm"


@pytest.mark.parametrize(
    ("array", "sidecar", "options", "message"),
    [
        (np.zeros((5, 17, 4)), None, {}, "D = 2 or 3"),
        (np.zeros((5, 17)), None, {}, "found shape (5, 17)"),
        (np.zeros((0, 17, 3)), None, {}, "no empty axis"),
        (np.zeros((5, 17, 3), dtype=bool), None, {}, "real numbers"),
        (np.full((5, 17, 3), np.inf), None, {}, "infinite"),
        (np.zeros((5, 17, 3)), None, {"topology": "kinect_v2"}, "17 joints, topology"),
        (np.zeros((5, 17, 3)), None, {"topology": "nope"}, "unknown topology"),
        (np.zeros((5, 17, 3)), None, {"fps": -3}, "frame rate"),
        (np.zeros((5, 17, 3)), None, {"units": "feet"}, "units must be"),
        (np.zeros((5, 17, 3)), {"topology": "coco", "rate": 30}, {}, "unknown keys ['rate']"),
        (np.zeros((5, 17, 3)), "{not json", {}, "unreadable sidecar"),
    ],
)
def test_bad_arrays_and_sidecars_are_read_errors(tmp_path, array, sidecar, options, message):
    p = tmp_path / "a.npy"
    np.save(p, array)
    if sidecar is not None:
        text = sidecar if isinstance(sidecar, str) else json.dumps(sidecar)
        (tmp_path / "a.json").write_text(text)
    with pytest.raises(ReadError, match=None) as err:
        read_npy(p, **options)
    assert message in str(err.value)


def test_pickled_objects_are_never_loaded(tmp_path):
    p = tmp_path / "obj.npy"
    np.save(p, np.array([{"x": 1}, None], dtype=object), allow_pickle=True)
    with pytest.raises(ReadError, match="not a readable NumPy array"):
        read_npy(p)


def test_an_archive_under_an_npy_name(tmp_path):
    p = tmp_path / "both.npz"
    np.savez(p, a=np.zeros((3, 2, 3)))
    q = p.rename(tmp_path / "both.npy")
    with pytest.raises(ReadError, match="archive"):
        read_npy(q)


@SETTINGS
@given(data=st.binary(max_size=300))
def test_arbitrary_bytes_after_the_magic(tmp_path, data):
    p = tmp_path / "f.npy"
    p.write_bytes(b"\x93NUMPY" + data)
    check_reader(read_npy, p)


@SETTINGS
@given(
    arr=arrays(
        st.sampled_from([np.float64, np.float32, np.int16]),
        st.tuples(st.integers(1, 6), st.integers(1, 5), st.sampled_from([2, 3])),
    )
)
def test_any_numeric_array_of_the_layout(tmp_path, arr):
    p = tmp_path / "f.npy"
    np.save(p, arr)
    check_reader(read_npy, p)
    if not np.isinf(arr).any() and np.nanmax(np.abs(arr.astype(float)), initial=0) < 1e8:
        (seq,) = read_npy(p)  # plausible values: read exactly
        np.testing.assert_array_equal(seq.positions, arr.astype(float))


def test_bone_gate_acts_only_with_the_skeleton(tmp_path):
    """A wrist that drifts 25 cm off its forearm within the speed bound: only the bone
    of the named skeleton (h36m17: RElbow -> RWrist) can tell it is impossible."""
    import tobitkf as tk

    topo = get_topology("h36m17")
    T = 90
    rest = np.array(
        [[0, 0.9, 3], [-0.1, 0.9, 3], [-0.1, 0.5, 3], [-0.1, 0.1, 3], [0.1, 0.9, 3],
         [0.1, 0.5, 3], [0.1, 0.1, 3], [0, 1.1, 3], [0, 1.35, 3], [0, 1.5, 3], [0, 1.6, 3],
         [0.18, 1.35, 3], [0.2, 1.07, 3], [0.22, 0.82, 3], [-0.18, 1.35, 3],
         [-0.2, 1.07, 3], [-0.22, 0.82, 3]],
    )  # fmt: skip
    rng = np.random.default_rng(1)
    arr = rest[None] + rng.normal(0, 0.003, (T, topo.n_joints, 3))
    wrist = topo.index("RWrist")
    drift = np.clip((np.arange(T) - 30) / 10, 0, 1) * (np.arange(T) < 70)  # 10 frames in
    arr[:, wrist, 0] -= 0.25 * drift  # 0.75 m/s at 30 fps: within the speed bound
    p = tmp_path / "drift.npy"
    np.save(p, arr)
    (tmp_path / "drift.json").write_text(json.dumps({"fps": 30, "units": "m"}))
    (bare,) = load(p)
    (named,) = load(p, topology="h36m")
    off = slice(42, 68)  # the wrist's bone is 25 cm (100 %) too long here
    rej_bare = tk.smooth(bare, "robust").metadata["diagnostics"]["rejected"]
    rej_named = tk.smooth(named, "robust").metadata["diagnostics"]["rejected"]
    assert not rej_bare[off, wrist].any()
    assert rej_named[off, wrist].all()


def test_cli_smooths_a_folder_with_its_sidecar(tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    np.save(src / "lifted.npy", _walk())
    (src / "lifted.json").write_text(json.dumps({"topology": "h36m17", "fps": 50}))
    np.save(src / "bare.npy", _walk(J=5))
    out = tmp_path / "out"
    run = subprocess.run(
        [sys.executable, "-m", "tobitkf", "smooth", str(src), "-o", str(out), "--json"],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    rows = {r["source"].rsplit("/", 1)[-1]: r for r in json.loads(run.stdout)}
    assert set(rows) == {"lifted.npy", "bare.npy"}  # the sidecar is not an input
    assert all(r["ok"] for r in rows.values())
    assert any("names no skeleton" in w for w in rows["bare.npy"]["warnings"])
    assert not any("skeleton" in w for w in rows["lifted.npy"]["warnings"])
    meta = json.loads((out / "lifted.robust.json").read_text())
    assert meta["topology"] == "h36m17" and meta["fps"] == 50.0


def test_editing_the_sidecar_redoes_the_output(tmp_path):
    import tobitkf as tk

    src = tmp_path / "in"
    src.mkdir()
    np.save(src / "a.npy", _walk())
    side = src / "a.json"
    side.write_text(json.dumps({"topology": "h36m17", "fps": 50}))
    out = tmp_path / "out"
    (first,) = tk.smooth_files(src, out)
    (again,) = tk.smooth_files(src, out)
    assert first.ok and again.extra.get("skipped")  # nothing changed: passed over
    side.write_text(json.dumps({"topology": "coco17", "fps": 50}))
    (edited,) = tk.smooth_files(src, out)
    assert edited.ok and not edited.extra.get("skipped")
    assert json.loads((out / "a.robust.json").read_text())["topology"] == "coco17"


def test_an_array_and_its_sidecar_named_by_urls(tmp_path):
    import tobitkf as tk

    fsspec = pytest.importorskip("fsspec", reason="fsspec is not installed")
    memory = fsspec.filesystem("memory")
    root = f"memory://tobitkf-npy-{tmp_path.name}"
    try:
        buf = tmp_path / "b.npy"
        np.save(buf, _walk())
        memory.pipe(f"{root}/in/b.npy", buf.read_bytes())
        memory.pipe(f"{root}/in/b.json", json.dumps({"topology": "h36m", "fps": 50}).encode())
        (res,) = tk.smooth_files(f"{root}/in", f"{root}/out")  # the sidecar is no input
        assert res.ok and res.source.endswith("/in/b.npy")
        meta = json.loads(memory.cat(f"{root}/out/b.robust.json"))
        assert meta["topology"] == "h36m17" and meta["fps"] == 50.0  # read with its array
    finally:
        if memory.exists(root):
            memory.rm(root, recursive=True)


def test_a_json_file_of_the_same_name_that_is_no_description(tmp_path):
    """clip.npy (lifted 3-D) beside clip.json (MMPose's 2-D predictions of the clip): the
    JSON file is a recording of its own, not the array's sidecar."""
    import tobitkf as tk

    np.save(tmp_path / "clip.npy", _walk())
    kp = _walk(T=10, D=2) * 100 + 300
    frames = [{"frame_id": t, "instances": [{"keypoints": kp[t].tolist(),
                                              "keypoint_scores": [0.9] * 17}]}
              for t in range(10)]  # fmt: skip
    (tmp_path / "clip.json").write_text(json.dumps(frames))
    (seq,) = load(tmp_path / "clip.npy")
    assert seq.topology.name == "unnamed"  # no description read
    res = {r.source.rsplit("/", 1)[-1]: r for r in tk.smooth_files(tmp_path, tmp_path / "o")}
    assert sorted(res) == ["clip.json", "clip.npy"] and res["clip.json"].ok
    # both would write clip.robust.csv: the second is refused with what to do
    assert "files named alike in one folder, clip.json and clip.npy" in res["clip.npy"].error
    (alone,) = tk.smooth_files(tmp_path / "clip.npy", tmp_path / "o2")
    assert alone.ok


def test_a_skeleton_for_the_files_that_name_none(tmp_path):
    """--topology (smooth_files(topology=)) names the joints of arrays without a sidecar;
    a file naming its own skeleton keeps it, and another --topology does not redo it."""
    import tobitkf as tk

    src = tmp_path / "in"
    src.mkdir()
    np.save(src / "lifted.npy", _walk())  # 17 unnamed joints
    named = tk.SkeletonSequence(_walk(J=25), tk.get_topology("kinect_v2"), fps=30.0)
    tk.save([named], src / "kinect.npz")
    out = tmp_path / "out"
    res = {r.source.rsplit("/", 1)[-1]: r for r in tk.smooth_files(src, out, topology="h36m")}
    assert all(r.ok for r in res.values())
    assert not any("skeleton" in w for w in res["lifted.npy"].warnings)  # no note: named
    assert json.loads((out / "lifted.robust.json").read_text())["topology"] == "h36m17"
    assert json.loads((out / "kinect.robust.json").read_text())["topology"] == "kinect_v2"
    again = tk.smooth_files(src, out, topology="coco17")  # another skeleton: the array only
    assert [r.source.rsplit("/", 1)[-1] for r in again if not r.extra.get("skipped")] == [
        "lifted.npy"
    ]
    assert json.loads((out / "lifted.robust.json").read_text())["topology"] == "coco17"
    with pytest.raises(KeyError, match="unknown topology"):
        tk.smooth_files(src, out, topology="nope")
    (wrong,) = tk.smooth_files(src / "lifted.npy", tmp_path / "o2", topology="kinect_v2")
    assert not wrong.ok and "17 keypoints, --topology kinect_v2 25" in wrong.error


def test_the_cli_topology_option(tmp_path):
    np.save(tmp_path / "a.npy", _walk())
    run = subprocess.run(
        [sys.executable, "-m", "tobitkf", "smooth", str(tmp_path / "a.npy"), "-o",
         str(tmp_path / "o"), "--topology", "h36m", "--fps", "50", "--json"],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    meta = json.loads((tmp_path / "o" / "a.robust.json").read_text())
    assert meta["topology"] == "h36m17" and meta["fps"] == 50.0
    bad = subprocess.run(
        [sys.executable, "-m", "tobitkf", "smooth", str(tmp_path / "a.npy"), "-o",
         str(tmp_path / "o"), "--topology", "nope"], capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert bad.returncode == 2 and "coco17" in bad.stderr  # the known names listed


def test_evaluate_and_report_name_what_the_array_does_not(tmp_path):
    """`evaluate` and `report` take --topology and --fps as `smooth` does: an array so
    named scores exactly as the same recording saved with its skeleton and rate."""
    from click.testing import CliRunner

    import tobitkf as tk
    from tobitkf.app.commands import app
    from tobitkf.core.jsonable import dumps
    from tobitkf.evaluation.evaluate import evaluate_paths

    arr = _walk(T=80)
    np.save(tmp_path / "a.npy", arr)
    named = tk.SkeletonSequence(arr, tk.get_topology("h36m17"), fps=50.0, units=None)
    tk.save([named], tmp_path / "named.npz")

    def scores(*args):
        res = CliRunner().invoke(app, ["evaluate", *args, "--methods", "raw,robust", "--json"])
        assert res.exit_code == 0, res.output
        return next(iter(json.loads(res.stdout).values()))

    given = scores(str(tmp_path / "a.npy"), "--topology", "h36m", "--fps", "50")
    assert given == scores(str(tmp_path / "named.npz"))
    _, table = evaluate_paths(tmp_path / "a.npy", None, ["raw", "robust"], topology="h36m", fps=50)
    assert json.loads(dumps(table.to_dict())) == given  # the library, as the CLI
    assert given != scores(str(tmp_path / "a.npy"), "--fps", "50")  # bones gate the robust
    assert given != scores(str(tmp_path / "a.npy"), "--topology", "h36m")  # 30 fps
    bad = CliRunner().invoke(app, ["evaluate", str(tmp_path / "a.npy"), "--topology", "kinect"])
    assert bad.exit_code == 1 and "17 keypoints, --topology kinect_v2 25" in bad.output

    out = tmp_path / "r.html"
    run = ["report", str(tmp_path / "a.npy"), "-o", str(out), "--no-gif", "--methods", "raw"]
    res = CliRunner().invoke(app, [*run, "--topology", "h36m17"])
    assert res.exit_code == 0, res.output
    joints = set(tk.get_topology("h36m17").joints)
    assert any(f" {j} frame " in res.output for j in joints)  # the largest jump's joint
    res = CliRunner().invoke(app, run)
    assert not any(f" {j} frame " in res.output for j in joints)

"""``implausible="missing"``: every reader takes it, ``load`` checks it, and
``tobitkf smooth --implausible missing`` smooths over such positions instead of failing
the file (recorded in the manifest and the output's provenance)."""

from __future__ import annotations

import inspect
import json

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

import tobitkf as tk
from tobitkf.app.commands import app
from tobitkf.app.manifest import MANIFEST_NAME, read_entries
from tobitkf.io import ReadError, load
from tobitkf.io._text import MAX_ABS_POSITION_M, MAX_ABS_POSITION_OTHER
from tobitkf.io.errors import OptionError
from tobitkf.io.registry import _FORMATS, register_format, unregister_format
from tobitkf.skeleton.sequence import SampleState

HUGE = 1e12  # beyond both bounds, whatever the unit


def test_every_registered_reader_takes_the_option():
    for name, spec in _FORMATS.items():
        if spec.reader is not None:
            assert "implausible" in inspect.signature(spec.reader).parameters, name


def test_load_checks_the_option_and_a_plugin_without_it(tmp_path):
    p = tmp_path / "x.plug"
    p.write_text("anything")
    seq = tk.generate_motion(duration=1.0)

    def reader(path):  # a plugin's reader, without the option
        return [seq]

    register_format("plug_no_option", reader, extensions=[".plug"])
    try:
        assert load(p, implausible="error")[0] is seq  # the default: nothing to ask
        with pytest.raises(OptionError, match="plug_no_option reader has no implausible"):
            load(p, implausible="missing")
        with pytest.raises(OptionError, match="implausible must be one of"):
            load(p, implausible="drop")
    finally:
        unregister_format("plug_no_option")


def _openpose(folder, kp):
    """One OpenPose frame file per frame of ``kp`` (T, J, 3: x, y, confidence)."""
    folder.mkdir()
    for t, k in enumerate(kp):
        person = {"person_id": [-1], "pose_keypoints_2d": [float(v) for v in k.ravel()]}
        doc = {"version": 1.3, "people": [person]}
        (folder / f"clip_{t:012d}_keypoints.json").write_text(json.dumps(doc))
    return folder


def _mmpose(path, kp):
    frames = [
        {
            "frame_id": t,
            "instances": [{"keypoints": k[:, :2].tolist(), "keypoint_scores": k[:, 2].tolist()}],
        }
        for t, k in enumerate(kp)
    ]
    path.write_text(json.dumps(frames))
    return path


def _mediapipe(path, kp):
    frames = [
        {
            "timestamp_ms": 33 * t,
            "pose_world_landmarks": [
                [
                    {"x": x, "y": y, "z": 0.5, "visibility": c, "presence": c}
                    for x, y, c in k.tolist()
                ]
            ],
        }
        for t, k in enumerate(kp)
    ]
    path.write_text(json.dumps({"frames": frames}))
    return path


def _npy(path, kp):
    np.save(path, kp[:, :, :2])
    return path


def _movement(path, kp):
    pytest.importorskip("xarray")
    from tobitkf.io.movement import _h5netcdf, to_movement

    def write_movement_ds(ds, p):
        ds.to_netcdf(p, engine=_h5netcdf())

    ok = np.where(np.abs(kp[:, :, :2]) > 1e6, 1.0, kp[:, :, :2])
    seq = tk.SkeletonSequence(
        ok, tk.get_topology("coco17"), fps=30.0, confidence=kp[:, :, 2], units="px"
    )
    ds = to_movement([seq])
    dims = ds["position"].dims
    pos = ds["position"].transpose("time", "individuals", "keypoints", "space")
    ds["position"] = pos.copy(data=kp[:, None, :, :2]).transpose(*dims)
    write_movement_ds(ds, path)
    return path


@pytest.mark.parametrize(
    ("name", "write", "joints", "bad"),
    [
        ("openpose", _openpose, 25, HUGE),
        ("mmpose", _mmpose, 17, HUGE),
        ("mediapipe", _mediapipe, 33, HUGE),
        ("npy", _npy, 17, HUGE),
        ("movement", _movement, 17, HUGE),
        ("movement", _movement, 17, np.inf),  # netCDF holds inf; JSON does not
    ],
)
def test_pose_readers_read_an_implausible_keypoint_as_missing(tmp_path, name, write, joints, bad):
    """Unlabelled people (OpenPose, MMPose, MediaPipe) are associated across frames: the
    keypoint must be missing before that, or the person splits in two."""
    rng = np.random.default_rng(1)
    kp = np.concatenate(
        [rng.uniform(0.1, 0.9, (6, joints, 2)), rng.uniform(0.5, 1.0, (6, joints, 1))], axis=2
    )
    if name != "mediapipe":  # pixels
        kp[:, :, :2] *= 500
    kp[3, 4, 1] = bad
    suffix = {"openpose": "", "npy": ".npy", "movement": ".nc"}.get(name, ".json")
    path = write(tmp_path / f"rec{suffix}", kp)
    kwargs = {"fps": 30.0} if name in ("openpose", "mmpose") else {}
    with pytest.raises(ReadError):
        load(path, format=name, **kwargs)
    (seq,) = load(path, format=name, implausible="missing", **kwargs)
    assert np.isnan(seq.positions[3, 4]).all()
    keep = np.ones(seq.positions.shape[:2], bool)
    keep[3, 4] = False
    np.testing.assert_allclose(seq.positions[keep][:, :2], kp[:, :, :2][keep], rtol=1e-6)


def test_the_help_states_the_bounds():
    res = CliRunner().invoke(app, ["smooth", "--help"], env={"COLUMNS": "200"})
    text = " ".join(res.output.split())
    assert f"{MAX_ABS_POSITION_M / 1000:g} km" in text
    assert f"{MAX_ABS_POSITION_OTHER:.0e} px".replace("e+0", "e") in text


def test_the_command_smooths_over_implausible_positions_when_asked(tmp_path):
    seq = tk.generate_motion(duration=3.0, seed=4)
    src = tmp_path / "in" / "walk.csv"
    src.parent.mkdir()
    tk.save(seq, src)
    df = pd.read_csv(src)  # wide: time, then x, y, z and state of each joint
    joint = seq.joint_names[7]
    df.loc[40, f"{joint}_x"] = HUGE
    df.to_csv(src, index=False)
    out = tmp_path / "out"
    args = ["smooth", str(src), "-o", str(out), "-m", "robust"]

    first = CliRunner().invoke(app, args)
    assert first.exit_code == 1
    assert "implausible position" in first.output and "--implausible missing" in first.output

    res = CliRunner().invoke(app, [*args, "--implausible", "missing"])
    assert res.exit_code == 0, res.output
    (done,) = tk.load(out / "walk.robust.csv")
    j = seq.joint_names.index(joint)
    assert done.sample_state[40, j] == SampleState.MISSING
    # filled from its neighbours: within 3 cm of the clean motion there
    assert np.linalg.norm(done.positions[40, j] - seq.positions[40, j]) < 0.03
    assert done.metadata["provenance"]["source"]["implausible"] == "missing"
    (entry,) = read_entries(out / MANIFEST_NAME).values()
    assert entry["status"] == "ok" and entry["params"]["input_implausible"] == "missing"

    again = CliRunner().invoke(app, [*args, "--implausible", "missing"])
    assert "passed over 1 file(s) done by an earlier run" in " ".join(again.output.split())
    # without the option the file is not the same job: it is redone (and fails)
    assert CliRunner().invoke(app, args).exit_code == 1


def test_smooth_files_checks_the_option_before_reading(tmp_path):
    with pytest.raises(OptionError, match="implausible must be one of"):
        tk.smooth_files(tmp_path, tmp_path / "out", implausible="drop")

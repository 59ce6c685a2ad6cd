"""Pose-estimator files written by the tools themselves (movement's DeepLabCut,
LightningPose and SLEAP writers, sleap-io's .slp and analysis writers, xarray's netCDF),
read back exactly; tobitkf's writers read by those tools; fuzzing of the text readers."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import tobitkf as tk
from tobitkf.io import ReadError

pd = pytest.importorskip("pandas")
xr = pytest.importorskip("xarray")
pytest.importorskip("tables")
load_poses = pytest.importorskip("movement.io.load_poses")
save_poses = pytest.importorskip("movement.io.save_poses")
sio = pytest.importorskip("sleap_io")

KP = ["snout", "left_ear", "right_ear", "tail_base"]


def _movement_ds(n_ind=2, T=12, D=2, seed=0, fps=None):
    """A movement dataset built by movement itself, with missing samples."""
    rng = np.random.default_rng(seed)
    pos = rng.uniform(0, 640, (T, D, len(KP), n_ind))
    pos[3, :, 1, 0] = np.nan
    pos[7, :, :, n_ind - 1] = np.nan  # a whole individual missing in a frame
    conf = rng.uniform(0, 1, (T, len(KP), n_ind))
    conf[np.isnan(pos[:, 0])] = np.nan
    names = [f"mouse{k}" for k in range(n_ind)]
    ds = load_poses.from_numpy(pos, conf, names, KP, fps=fps, source_software="test")
    return ds, pos, conf, names


def _check(seqs, pos, conf, names, *, conf_for_missing=None):
    """Sequences equal the arrays (time, space, keypoints, individuals) exactly."""
    assert [s.body_id for s in seqs] == names
    for i, s in enumerate(seqs):
        assert s.joint_names == tuple(KP)
        np.testing.assert_array_equal(s.positions, pos[..., i].transpose(0, 2, 1))
        if conf is not None:
            want = conf[..., i].copy()
            if conf_for_missing is not None:
                want[np.isnan(pos[:, 0, :, i])] = conf_for_missing
            np.testing.assert_array_equal(s.confidence, want)


@pytest.mark.parametrize("suffix", [".h5", ".csv"])
def test_deeplabcut_multi_animal_written_by_movement(tmp_path, suffix):
    ds, pos, conf, names = _movement_ds()
    path = tmp_path / f"pred{suffix}"
    save_poses.to_dlc_file(ds, path, split_individuals=False)
    assert tk.detect_format(path) == "deeplabcut"
    seqs = tk.load(path)
    _check(seqs, pos, conf, names)
    assert all(s.units == "px" and s.n_dims == 2 for s in seqs)
    assert seqs[0].metadata["scorer"] == "movement"


@pytest.mark.parametrize("suffix", [".h5", ".csv"])
def test_deeplabcut_single_animal_written_by_movement(tmp_path, suffix):
    ds, pos, conf, _ = _movement_ds(n_ind=1, fps=25)
    path = tmp_path / f"pred{suffix}"
    save_poses.to_dlc_file(ds, path, split_individuals=True)
    (written,) = tmp_path.glob(f"pred_*{suffix}")
    (s,) = tk.load(written, fps=25)
    assert s.body_id is None and s.fps == 25.0
    _check([s], pos, conf, [None])


def test_lightningpose_written_by_movement(tmp_path):
    ds, pos, conf, _ = _movement_ds(n_ind=1)
    save_poses.to_lp_file(ds, tmp_path / "lp.csv")
    (written,) = tmp_path.glob("lp_*.csv")
    # movement's scorer is "movement": the content reads as DeepLabCut, the format can be named
    (s,) = tk.load(written, format="lightningpose")
    assert s.metadata["format"] == "lightningpose"
    _check([s], pos, conf, [None])


def test_sleap_analysis_written_by_movement(tmp_path):
    ds, pos, conf, names = _movement_ds()
    path = tmp_path / "pred.analysis.h5"
    save_poses.to_sleap_analysis_file(ds, path)
    assert tk.detect_format(path) == "sleap_analysis"
    _check(tk.load(path), pos, conf, names)


def _sleap_labels(T=6, seed=1):
    rng = np.random.default_rng(seed)
    nodes = [sio.Node(n) for n in KP]
    skel = sio.Skeleton(
        nodes=nodes,
        edges=[sio.Edge(nodes[0], nodes[1]), sio.Edge(nodes[0], nodes[2]),
               sio.Edge(nodes[0], nodes[3])],
        symmetries=[sio.Symmetry([nodes[1], nodes[2]])],
    )  # fmt: skip
    video = sio.Video(filename="fake.mp4")
    tracks = [sio.Track("fly1"), sio.Track("fly2")]
    frames = []
    for t in range(T):
        insts = []
        for k, tr in enumerate(tracks):
            pts = rng.uniform(0, 500, (len(KP), 2))
            if (t, k) == (2, 1):
                pts[3] = np.nan
            scores = rng.uniform(0, 1.2, len(KP))
            insts.append(sio.PredictedInstance.from_numpy(pts, skel, point_scores=scores, track=tr))
        frames.append(sio.LabeledFrame(video=video, frame_idx=t, instances=insts))
    return sio.Labels(labeled_frames=frames, videos=[video], skeletons=[skel], tracks=tracks)


@pytest.mark.parametrize("how", ["slp", "analysis_matlab", "analysis_standard"])
def test_sleap_files_written_by_sleap_io(tmp_path, how):
    labels = _sleap_labels()
    arr = labels.numpy(return_confidence=True)  # (frames, tracks, nodes, 3), as sleap-io sees it
    if how == "slp":
        path = tmp_path / "p.slp"
        sio.save_slp(labels, path)
    else:
        path = tmp_path / "p.analysis.h5"
        sio.save_analysis_h5(labels, path, preset=how.split("_")[1])
    seqs = tk.load(path)
    assert [s.body_id for s in seqs] == ["fly1", "fly2"]
    # Labels.numpy gives float32; the analysis file holds the float64 values: equal to
    # float32 resolution (2^-24 relative)
    tol = 0 if how == "slp" else 2.0**-23
    for k, s in enumerate(seqs):
        np.testing.assert_allclose(s.positions, arr[:, k, :, :2], rtol=tol, atol=0)
        np.testing.assert_allclose(s.confidence, np.clip(arr[:, k, :, 2], 0, 1), rtol=tol)
        assert s.topology.parents == (-1, 0, 0, 0)  # the skeleton's edges
        assert sorted(map(sorted, s.topology.symmetry)) == [[1, 2]]
    assert np.isnan(seqs[1].positions[2, 3]).all()
    assert seqs[0].metadata["confidence_clipped"]  # sleap's scores above 1 were clipped


def test_movement_netcdf_and_objects(tmp_path):
    ds, pos, conf, names = _movement_ds(fps=30)
    path = tmp_path / "poses.nc"
    ds.to_netcdf(path, engine="h5netcdf")  # how movement users save a dataset
    assert tk.detect_format(path) == "movement"
    seqs = tk.load(path)
    _check(seqs, pos, conf, names)
    assert seqs[0].fps == 30.0 and seqs[0].timestamps is None
    _check(tk.from_movement(ds), pos, conf, names)
    # back: a dataset movement accepts, equal to the original
    back = tk.to_movement(seqs)
    from movement.validators.datasets import ValidPosesInputs

    ValidPosesInputs.validate(back)
    xr.testing.assert_equal(back["position"], ds["position"])
    xr.testing.assert_equal(back["confidence"], ds["confidence"])
    assert back.attrs["fps"] == 30.0


def test_writers_read_by_the_tools(tmp_path):
    """tobitkf's DeepLabCut, LightningPose and movement outputs, read by movement."""
    ds = _movement_ds(fps=30)[0]
    seqs = tk.smooth(tk.from_movement(ds))  # smoothed: every sample filled in
    for name, suffix, reader in [
        ("deeplabcut", ".h5", load_poses.from_dlc_file),
        ("deeplabcut", ".csv", load_poses.from_dlc_file),
        ("movement", ".nc", None),
    ]:
        path = tmp_path / f"out{suffix}"
        tk.save(seqs, path, format=name)
        back = tk.load(path)
        for a, b in zip(seqs, back, strict=True):
            np.testing.assert_allclose(b.positions, a.positions, rtol=1e-15)
            assert b.body_id == a.body_id
        if reader is not None:
            theirs = reader(path, fps=30)
            np.testing.assert_allclose(
                theirs["position"].values,
                np.stack([s.positions for s in seqs], -1).transpose(0, 2, 1, 3),
                rtol=1e-15,
            )
    one = seqs[0]
    tk.save([one], tmp_path / "lp.csv", format="lightningpose")
    theirs = load_poses.from_lp_file(tmp_path / "lp.csv")
    np.testing.assert_allclose(theirs["position"].values[..., 0], one.positions.transpose(0, 2, 1))
    # likelihood: the confidence where given, NaN where the position is missing
    raw = tk.from_movement(ds)[0]
    tk.save([raw], tmp_path / "raw.csv", format="deeplabcut")
    (r,) = tk.load(tmp_path / "raw.csv")
    np.testing.assert_array_equal(r.confidence, raw.confidence)


def test_pose_readers_errors(tmp_path):
    bad = tmp_path / "x.h5"
    bad.write_bytes(b"\x89HDF\r\n\x1a\n" + b"\0" * 100)
    with pytest.raises(ReadError, match=r"x\.h5"):
        tk.load(bad, format="deeplabcut")
    with pytest.raises(ReadError, match=r"x\.h5"):
        tk.load(bad, format="sleap_analysis")
    csv = tmp_path / "d.csv"
    csv.write_text("scorer,a,a\nbodyparts,p,p\ncoords,x,q\n0,1,2\n")
    with pytest.raises(ReadError, match="unknown coords"):
        tk.load(csv)
    with pytest.raises(TypeError, match="xarray Dataset"):
        tk.from_movement({"position": 1})


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(body=st.binary(max_size=300))
def test_deeplabcut_csv_fuzz(tmp_path, body):
    """Arbitrary bytes after a DeepLabCut header: a ReadError or sequences, nothing else."""
    path = tmp_path / "f.csv"
    path.write_bytes(b"scorer,s,s,s\nbodyparts,a,a,a\ncoords,x,y,likelihood\n" + body)
    try:
        seqs = tk.load(path, format="deeplabcut")
    except ReadError:
        return
    for s in seqs:
        assert s.n_dims == 2

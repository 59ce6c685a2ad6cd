"""Pose-estimator files written by the tools themselves (movement's DeepLabCut,
LightningPose and SLEAP writers, sleap-io's .slp and analysis writers, xarray's netCDF),
read back exactly; tobitkf's writers read by those tools; fuzzing of the text readers."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import tobitkf as tk
from tobitkf.core.jsonable import to_jsonable
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


def test_sleap_files_are_known_by_their_content_not_their_name(tmp_path):
    """An analysis file named .slp and a .slp named .h5 (content first, extension
    second): each is read as what it holds."""
    labels = _sleap_labels()
    sio.save_slp(labels, tmp_path / "labels.h5")
    sio.save_analysis_h5(labels, tmp_path / "analysis.slp")
    assert tk.detect_format(tmp_path / "labels.h5") == "slp"
    assert tk.detect_format(tmp_path / "analysis.slp") == "sleap_analysis"
    for name in ("labels.h5", "analysis.slp"):
        assert [s.body_id for s in tk.load(tmp_path / name)] == ["fly1", "fly2"]


def test_a_sleap_project_of_two_videos(tmp_path):
    """One sequence per video and track: the CSV keeps which video each came from; a
    pose format of one video refuses them, naming the videos."""
    labels = _sleap_labels()
    other = sio.Video(filename="other.mp4")
    skel, track = labels.skeletons[0], labels.tracks[0]
    rng = np.random.default_rng(7)
    labels.videos.append(other)
    for t in range(9):
        pts = rng.uniform(0, 500, (len(KP), 2))
        inst = sio.PredictedInstance.from_numpy(pts, skel, point_scores=np.ones(4), track=track)
        labels.labeled_frames.append(sio.LabeledFrame(video=other, frame_idx=t, instances=[inst]))
    sio.save_slp(labels, tmp_path / "two.slp")
    seqs = tk.load(tmp_path / "two.slp")
    videos = [s.metadata["video"] for s in seqs]
    assert sorted(set(videos)) == ["fake.mp4", "other.mp4"]
    tk.save(seqs, tmp_path / "two.csv", format="csv")
    back = tk.load(tmp_path / "two.csv")
    assert [s.metadata["video"] for s in back] == videos
    assert [s.n_frames for s in back] == [s.n_frames for s in seqs]
    for fmt, suffix in (("deeplabcut", ".h5"), ("movement", ".nc"), ("mmpose", ".json")):
        with pytest.raises(ValueError, match=r"come from 2 videos .*fake\.mp4"):
            tk.save(seqs, tmp_path / f"two{suffix}", format=fmt)


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


def test_filled_samples_are_written_with_score_zero(tmp_path):
    """A smoother's fills carry no detection: DeepLabCut, LightningPose and movement get
    likelihood 0 there (read back by movement itself), measured samples keep theirs."""
    ds, pos, conf, _ = _movement_ds(fps=30)
    seqs = tk.smooth(tk.from_movement(ds))
    gone = np.isnan(pos[:, 0]).transpose(2, 0, 1)  # (individual, T, keypoint) not detected
    filled = np.stack([tk.SampleState.filled(s.sample_state) for s in seqs])
    measured = np.stack([s.sample_state == tk.SampleState.MEASURED for s in seqs])
    assert (gone & filled).any() and measured.any()
    assert not (measured & gone).any()
    for name, suffix, reader in [
        ("deeplabcut", ".h5", load_poses.from_dlc_file),
        ("deeplabcut", ".csv", load_poses.from_dlc_file),
        ("movement", ".nc", lambda p, fps: xr.open_dataset(p, engine="h5netcdf")),
    ]:
        path = tmp_path / f"out{suffix}"
        tk.save(seqs, path, format=name)
        theirs = reader(path, fps=30)["confidence"].values.transpose(2, 0, 1)
        assert (theirs[filled] == 0).all()
        np.testing.assert_array_equal(theirs[measured], conf.transpose(2, 0, 1)[measured])
    tk.save([seqs[1]], tmp_path / "lp.csv", format="lightningpose")
    theirs = load_poses.from_lp_file(tmp_path / "lp.csv")["confidence"].values[..., 0]
    assert (theirs[filled[1]] == 0).all()


def test_deeplabcut_unique_bodyparts_written_back(tmp_path):
    """A multi-animal project's ``single`` individual (unique body parts) keeps its own
    body parts in the DeepLabCut and CSV outputs; movement's one array refuses it."""
    T, scorer = 40, "DLC_dlcrnetms5_maSep1shuffle1_100000"
    rng = np.random.default_rng(3)
    cols, data = [], []
    for ind, parts in (
        ("m1", ["snout", "tail"]),
        ("m2", ["snout", "tail"]),
        ("single", ["A", "B"]),
    ):
        for part in parts:
            for c in ("x", "y", "likelihood"):
                cols.append((scorer, ind, part, c))
                v = (
                    rng.uniform(0.5, 1, T)
                    if c == "likelihood"
                    else 100 + np.cumsum(rng.normal(0, 1, T))
                )
                data.append(v)
    index = pd.MultiIndex.from_tuples(cols, names=["scorer", "individuals", "bodyparts", "coords"])
    df = pd.DataFrame(np.array(data).T, columns=index)
    src = tmp_path / "ma.h5"
    df.to_hdf(src, key="df_with_missing", format="table", mode="w")
    seqs = tk.load(src, fps=30)
    assert [s.joint_names for s in seqs] == [("snout", "tail")] * 2 + [("A", "B")]
    out = tmp_path / "out.h5"
    tk.save(seqs, out, format="deeplabcut")
    back = pd.read_hdf(out)
    assert list(back.columns) == list(df.columns)
    np.testing.assert_array_equal(back.values, df.values)
    tk.save(seqs, tmp_path / "out.csv", format="csv")
    for a, b in zip(seqs, tk.load(tmp_path / "out.csv"), strict=True):
        assert (b.body_id, b.joint_names) == (a.body_id, a.joint_names)
        np.testing.assert_array_equal(b.positions, a.positions)
    with pytest.raises(ValueError, match=r"different keypoints.*single: A, B"):
        tk.save(seqs, tmp_path / "out.nc", format="movement")


def test_frame_numbers_are_written_back(tmp_path):
    """A movement dataset timed in frames and cut to frames 50..61, and a DeepLabCut
    table whose rows are numbered from 50, keep their frame numbers in the outputs."""
    ds = _movement_ds(T=62)[0].isel(time=slice(50, 62))
    ds.attrs = {k: v for k, v in ds.attrs.items() if v is not None}
    ds.to_netcdf(tmp_path / "in.nc", engine="h5netcdf")
    seqs = tk.load(tmp_path / "in.nc")
    tk.save(seqs, tmp_path / "out.nc", format="movement")
    with xr.open_dataset(tmp_path / "out.nc", engine="h5netcdf") as out:
        assert out.attrs["time_unit"] == "frames"
        np.testing.assert_array_equal(out["time"].values, np.arange(50, 62))
    save_poses.to_dlc_file(_movement_ds()[0], tmp_path / "in.h5", split_individuals=False)
    df = pd.read_hdf(tmp_path / "in.h5")
    df.index = np.arange(50, 50 + len(df))
    df.to_hdf(tmp_path / "in50.h5", key="df_with_missing", format="table", mode="w")
    tk.save(tk.load(tmp_path / "in50.h5"), tmp_path / "out.h5", format="deeplabcut")
    np.testing.assert_array_equal(pd.read_hdf(tmp_path / "out.h5").index, df.index)


def test_a_deeplabcut_csv_cut_short_is_a_read_error(tmp_path):
    """pandas fills a short row with NaN: a file cut within a row (its last number cut
    too) is refused at that line, as is a short row anywhere."""
    ds = _movement_ds()[0]
    path = tmp_path / "pred.csv"
    save_poses.to_dlc_file(ds, path, split_individuals=False)
    text = path.read_text()
    lines = text.splitlines()
    (tmp_path / "cut.csv").write_text(text[: len(text) - len(lines[-1]) // 2 - 1])
    with pytest.raises(ReadError, match="ends within this row") as e:
        tk.load(tmp_path / "cut.csv")
    assert e.value.line == len(lines)
    lines[6] = lines[6].rsplit(",", 2)[0]
    (tmp_path / "short.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(ReadError, match="fields as in the header") as e:
        tk.load(tmp_path / "short.csv")
    assert e.value.line == 7


def test_movement_output_keeps_the_sd_the_sample_states_and_the_pairs(tmp_path):
    """A smoothed sequence's sd and sample states, and its left/right pairs, come back
    from the netCDF file; movement itself still takes the dataset (to its DLC file)."""
    ds = _movement_ds(fps=30)[0]
    # a pair the names do not tell (the reader would find left_ear / right_ear itself)
    topo = tk.Topology.from_names(KP, [-1, 0, 0, 0], symmetry=[(0, 3)])
    seqs = [s.replace(topology=topo) for s in tk.smooth(tk.from_movement(ds))]
    tk.save(seqs, tmp_path / "out.nc", format="movement")
    back = tk.load(tmp_path / "out.nc")
    for a, b in zip(seqs, back, strict=True):
        np.testing.assert_array_equal(b.std, a.std)
        np.testing.assert_array_equal(b.sample_state, a.sample_state)
        assert b.topology.symmetry == ((0, 3),) and b.topology.parents == topo.parents
    with xr.open_dataset(tmp_path / "out.nc", engine="h5netcdf") as theirs:
        save_poses.to_dlc_file(theirs.load(), tmp_path / "dlc.h5", split_individuals=False)
    np.testing.assert_allclose(
        load_poses.from_dlc_file(tmp_path / "dlc.h5")["position"].values,
        np.stack([s.positions for s in seqs], -1).transpose(0, 2, 1, 3),
    )


def _without_provenance(seq):
    return seq.replace(metadata={k: v for k, v in seq.metadata.items() if k != "provenance"})


@pytest.mark.parametrize("fmt, suffix", [("movement", ".nc"), ("deeplabcut", ".h5")])
def test_pose_outputs_keep_the_provenance(tmp_path, fmt, suffix):
    """movement's netCDF (a dataset attribute) and DeepLabCut's .h5 (attributes of the
    table's group) keep the provenance, robust's long one, read back equal: the one the
    individuals share, or each one's own (one without); movement, xarray and
    pandas.read_hdf still read the files."""
    ds, pos, _, names = _movement_ds(fps=30)
    seqs = tk.smooth(tk.from_movement(ds), method="robust")
    provs = [to_jsonable(s.metadata["provenance"]) for s in seqs]  # NaN is null in JSON
    assert len(json.dumps(provs[0])) > 255 and provs[0] == provs[1]  # shared: one JSON
    own = [seqs[0].replace(metadata={**seqs[0].metadata, "provenance": {"method": "kf"}}),
           _without_provenance(seqs[1])]  # fmt: skip
    for case, want in ((seqs, provs), (own, [{"method": "kf"}, None])):
        path = tmp_path / f"out{suffix}"
        tk.save(case, path, format=fmt)
        back = tk.load(path)
        assert [s.metadata.get("provenance") for s in back] == want
        if fmt == "movement":
            from movement.validators.datasets import ValidPosesInputs

            with xr.open_dataset(path, engine="h5netcdf") as theirs:
                ValidPosesInputs.validate(theirs)  # as movement's napari loader opens .nc
                text = theirs.attrs["tobitkf_provenance"]
                xr.testing.assert_equal(theirs["position"], tk.to_movement(case)["position"])
        else:
            df = pd.read_hdf(path)  # DeepLabCut's own read: no key, one table
            assert df.shape == (len(pos), len(names) * len(KP) * 3)
            with pd.HDFStore(path, mode="r") as store:
                text = store.get_storer("df_with_missing").attrs.tobitkf_provenance
            theirs = load_poses.from_dlc_file(path, fps=30)
            np.testing.assert_array_equal(
                theirs["position"].values,
                np.stack([s.positions for s in case], -1).transpose(0, 2, 1, 3),
            )
        doc = json.loads(text)
        assert doc == (want[0] if case is seqs else want)
    assert json.loads(tk.to_movement(seqs).attrs["tobitkf_provenance"]) == provs[0]
    assert tk.from_movement(tk.to_movement(own))[0].metadata["provenance"] == {"method": "kf"}


def test_long_provenance_in_deeplabcut_h5_and_movement_nc(tmp_path):
    """An HDF5 attribute holds at most 64 KB: DeepLabCut's .h5 splits longer JSON into
    tobitkf_provenance, tobitkf_provenance_2, ...; netCDF keeps one attribute."""
    ds = _movement_ds(fps=30)[0]
    seqs = tk.smooth(tk.from_movement(ds), method="robust")
    long = to_jsonable({**seqs[0].metadata["provenance"], "note": "x" * 100000})
    seqs = [s.replace(metadata={**s.metadata, "provenance": long}) for s in seqs]
    for fmt, suffix in (("deeplabcut", ".h5"), ("movement", ".nc")):
        path = tmp_path / f"long{suffix}"
        tk.save(seqs, path, format=fmt)
        assert [s.metadata["provenance"] for s in tk.load(path)] == [long, long]
    with pd.HDFStore(tmp_path / "long.h5", mode="r") as store:
        attrs = store.get_storer("df_with_missing").attrs._v_attrnames
    assert {"tobitkf_provenance", "tobitkf_provenance_2", "tobitkf_provenance_4"} <= set(attrs)
    assert pd.read_hdf(tmp_path / "long.h5").shape[0] == seqs[0].n_frames


@pytest.mark.parametrize("fmt, suffix", [("movement", ".nc"), ("deeplabcut", ".h5")])
def test_a_pose_file_named_like_an_output_is_one_only_by_its_provenance(tmp_path, fmt, suffix):
    """``mice.kinect.nc`` / ``.h5`` written by movement is a recording ('kinect' is a
    method name); tobitkf's output is an earlier output of the method its provenance
    names, whatever its name says."""
    from tobitkf.app.batch import smoothing_output_method

    ds = _movement_ds(fps=30)[0]
    theirs = tmp_path / f"mice.kinect{suffix}"
    if fmt == "movement":
        ds.to_netcdf(theirs, engine="h5netcdf")
    else:
        save_poses.to_dlc_file(ds, theirs, split_individuals=False)
    assert smoothing_output_method(theirs) is None
    ours = tmp_path / f"mice.kf{suffix}"
    tk.save(tk.smooth(tk.from_movement(ds), method="kf"), ours, format=fmt)
    assert smoothing_output_method(ours) == "kf"
    renamed = ours.rename(tmp_path / f"mice.sgf{suffix}")
    assert smoothing_output_method(renamed) is None


def test_pose_provenance_that_is_not_json_is_a_read_error(tmp_path):
    ds = _movement_ds(fps=30)[0]
    bad = ds.assign_attrs(tobitkf_provenance="{oops")
    with pytest.raises(ReadError, match="tobitkf_provenance is not the provenance's JSON"):
        tk.from_movement(bad)
    three = ds.assign_attrs(tobitkf_provenance="[{}, {}, {}]")
    with pytest.raises(ReadError, match="a list of 2 \\(one per body\\), found an array of 3"):
        tk.from_movement(three)


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


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    body=st.binary(max_size=200),
    hdf5=st.booleans(),
    fmt=st.sampled_from(["deeplabcut", "sleap_analysis", "movement", "slp", "lightningpose"]),
)
def test_binary_pose_readers_fuzz(tmp_path, body, hdf5, fmt):
    """Arbitrary bytes (with or without the HDF5 signature) named as a pose file: a
    ReadError naming the file, never another exception."""
    path = tmp_path / ("f.slp" if fmt == "slp" else "f.csv" if fmt == "lightningpose" else "f.h5")
    path.write_bytes((b"\x89HDF\r\n\x1a\n" if hdf5 else b"") + body)
    try:
        tk.load(path, format=fmt)
    except ReadError as exc:
        assert str(path) in str(exc)


def test_missing_optional_package_names_the_extra(tmp_path, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "h5py", None)  # import h5py now raises ImportError
    path = tmp_path / "x.analysis.h5"
    path.write_bytes(b"\x89HDF\r\n\x1a\n" + b"\0" * 64)
    with pytest.raises(ImportError, match=r"pip install 'tobitkf\[pose\]'"):
        tk.load(path, format="sleap_analysis")
    monkeypatch.setitem(sys.modules, "sleap_io", None)
    with pytest.raises(ImportError, match=r"pip install 'tobitkf\[slp\]'"):
        tk.load(path, format="slp")


def test_without_h5py_a_sleap_analysis_file_is_not_taken_for_deeplabcut(tmp_path, monkeypatch):
    # the DeepLabCut sniffer claimed every .h5 it could not open, so a SLEAP analysis
    # file asked for pandas, then tables, then h5py, each in turn
    import sys

    from tobitkf.io import detect_format

    monkeypatch.setitem(sys.modules, "h5py", None)
    for name, fmt in (("x.analysis.h5", "sleap_analysis"), ("mouseDLC_resnet50.h5", "deeplabcut")):
        path = tmp_path / name
        path.write_bytes(b"\x89HDF\r\n\x1a\n" + b"\0" * 64)
        assert detect_format(path) == fmt
    with pytest.raises(ImportError, match="h5py"):
        tk.load(tmp_path / "x.analysis.h5")


def test_a_netcdf4_file_without_h5netcdf_names_the_package(tmp_path, monkeypatch):
    # "(or pip install xarray)" was followed, and the valid file was then called "not a
    # movement poses netCDF file": the netCDF-4 (HDF5) library was what was missing
    import sys

    pytest.importorskip("h5netcdf")
    y = np.random.default_rng(0).normal(size=(10, 3, 2))
    seq = tk.SkeletonSequence(y, tk.Topology.from_names(["a", "b", "c"]), fps=30, units="px")
    tk.save([seq], tmp_path / "m.nc", format="movement")
    monkeypatch.setitem(sys.modules, "h5netcdf", None)
    monkeypatch.setitem(sys.modules, "netCDF4", None)
    with pytest.raises(ImportError, match=r"h5netcdf.*pip install 'tobitkf\[pose\]'"):
        tk.load(tmp_path / "m.nc")

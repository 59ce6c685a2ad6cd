"""Uncertainty, sample states and provenance of smoothed output (issue 10, points 5, 6).

Every smoothed sample carries a posterior standard deviation (methods that give one) and
a SampleState; every output records the tobitkf version, the method and the complete
parameters; CSV output is a plain table (pandas reads it with no options) with a JSON
sidecar; NPZ keeps everything; NTU marks filled joints inferred.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

import tobitkf as tk
from conftest import data_file
from tobitkf.app.batch import plan_jobs
from tobitkf.app.commands import app
from tobitkf.io import load, save
from tobitkf.io.generic_csv import read_csv, sidecar_path, write_csv
from tobitkf.io.npz import read_npz, write_npz
from tobitkf.io.ntu import read_ntu, write_ntu
from tobitkf.skeleton.sequence import SampleState, SkeletonSequence, TrackingState
from tobitkf.skeleton.topology import Topology, get_topology

M, R, X, N = (int(s) for s in (SampleState.MEASURED, SampleState.REJECTED,
                                SampleState.MISSING, SampleState.EXTRAPOLATED))  # fmt: skip
NONE = int(SampleState.NONE)
ROOT = Path(__file__).resolve().parents[1]


def _gappy(states: bool = False) -> SkeletonSequence:
    """Two joints, 10 frames at 30 fps. Joint ``a``: no measurement at frames 0-1 (before
    the first), measured 2-4, a gap at 5-6, measured 7, nothing after (8-9). Joint ``b``:
    measured throughout."""
    T = 10
    t = np.arange(T)[:, None]
    pos = np.concatenate([np.hstack([0.01 * t, 0 * t, 2 + 0 * t])[:, None]] * 2, axis=1)
    pos[[0, 1, 5, 6, 8, 9], 0] = np.nan
    topo = Topology.from_names(["a", "b"], up_axis=1, name="pair")
    st = None
    if states:
        st = np.full((T, 2), int(TrackingState.TRACKED), dtype=np.int8)
        st[np.isnan(pos).any(axis=-1)] = TrackingState.NOT_TRACKED
        st[3, 1] = TrackingState.INFERRED
    return SkeletonSequence(pos, topo, st, fps=30.0, metadata={"source": "x.csv"})


# ---------------------------------------------------------------- sample states


def test_sample_states_offline_gap_is_missing_and_ends_extrapolated_or_none():
    out = tk.smooth(_gappy(), method="kf", offline=True)
    # kf gives no estimate before a joint's first measurement; RTS interpolates the gap
    assert out.sample_state[:, 0].tolist() == [NONE, NONE, M, M, M, X, X, M, N, N]
    assert (out.sample_state[:, 1] == M).all()


def test_sample_states_causal_fills_are_extrapolated():
    out = tk.smooth(_gappy(), method="kf")  # causal: every fill is a prediction
    assert out.sample_state[:, 0].tolist() == [NONE, NONE, M, M, M, N, N, M, N, N]


def test_tracking_state_of_output_follows_sample_state():
    # no input states: measured -> TRACKED, filled -> INFERRED, no estimate -> NOT_TRACKED
    out = tk.smooth(_gappy(), method="kf", offline=True)
    T_, I_, N_ = (int(s) for s in (TrackingState.TRACKED, TrackingState.INFERRED,
                                   TrackingState.NOT_TRACKED))  # fmt: skip
    assert out.tracking_state[:, 0].tolist() == [N_, N_, T_, T_, T_, I_, I_, T_, I_, I_]
    # input states: a measured INFERRED sample stays INFERRED, NOT_TRACKED gaps become INFERRED
    out = tk.smooth(_gappy(states=True), method="kf", offline=True)
    assert out.tracking_state[:, 0].tolist() == [N_, N_, T_, T_, T_, I_, I_, T_, I_, I_]
    assert out.tracking_state[3, 1] == I_ and (np.delete(out.tracking_state[:, 1], 3) == T_).all()
    # nothing filled and no input states: none invented
    full = _gappy().replace(positions=np.nan_to_num(_gappy().positions, nan=1.0))
    assert tk.smooth(full, method="kf").tracking_state is None


@pytest.fixture
def flagging_method():
    """A user method that rejects the samples it is told to, fills by holding the last
    output, and is causal or not by a parameter: the sample states are computed by
    ``smooth`` for every method alike."""

    def run(inp, reject_frame, causal):
        rejected = np.zeros(inp.missing.shape, dtype=bool)
        rejected[reject_frame] = True
        ys = np.where(rejected[..., None], np.nan, inp.ys)
        out = ys.copy()
        for t in range(1, len(out)):
            out[t] = np.where(np.isnan(out[t]), out[t - 1], out[t])
        diags = tuple({"rejected": rejected[:, b]} for b in range(ys.shape[1]))
        return tk.SmoothOutput(out, diagnostics=diags)

    tk.register_method(
        "test_flagging", run, params={"reject_frame": 3, "causal": False},
        causal=lambda p: p["causal"],
    )  # fmt: skip
    yield "test_flagging"
    tk.unregister_method("test_flagging")


def test_rejected_samples_are_rejected_for_any_method(flagging_method):
    out = tk.smooth(_gappy(), method=flagging_method)
    assert out.sample_state[3].tolist() == [R, R]
    # the hold fill of a non-causal method between two used measurements counts as missing
    assert out.sample_state[:, 0].tolist() == [NONE, NONE, M, R, M, X, X, M, N, N]
    assert out.std is None  # the method gives none
    causal = tk.smooth(_gappy(), method=flagging_method, causal=True)
    assert causal.sample_state[:, 0].tolist() == [NONE, NONE, M, R, M, N, N, M, N, N]
    assert (causal.tracking_state[3] == TrackingState.INFERRED).all()


def test_kimore_robust_rejections_are_rejected_and_inferred(tmp_path):
    seq = load(data_file("kimore/JointPositionExercise3.csv"))[0]
    out = tk.smooth(seq, method="robust")
    rejected = np.asarray(out.metadata["diagnostics"]["rejected"], dtype=bool)
    assert rejected.sum() > 1000  # the recording's hand glitches (issue 10: 2,667)
    assert (out.sample_state[rejected] == R).all()
    assert (out.tracking_state[rejected] == TrackingState.INFERRED).all()
    # before: these samples kept the input's state, mostly TRACKED
    assert (seq.tracking_state[rejected] == TrackingState.TRACKED).any()
    # and the written CSV says so in its state and sample columns
    p = tmp_path / "ex3.robust.csv"
    save(out, p)
    df = pd.read_csv(p)
    j = np.flatnonzero(rejected.any(axis=0))[0]
    name = seq.joint_names[j]
    rows = rejected[:, j]
    assert (df[f"{name}_sample"].to_numpy()[rows] == R).all()
    assert (df[f"{name}_state"].to_numpy()[rows] == 1).all()


# ---------------------------------------------------------------- std


def _scalar_kf(y, q, r, r_scale, rts):
    """Variance of a 1-D random-walk Kalman filter written out by hand: prior x0 (the
    first measurement), P0 = r before frame 0; each frame predicts P += q and, when
    measured, updates P = P r_k / (P + r_k); RTS: Ps = P + G^2 (Ps' - P'), G = P / P'."""
    P, Ppred, out = r, [], []
    for k in range(len(y)):
        P = P + q
        Ppred.append(P)
        if not np.isnan(y[k]):
            rk = r * r_scale[k]
            P = P * rk / (P + rk)
        out.append(P)
    if rts:
        for k in range(len(y) - 2, -1, -1):
            G = out[k] / Ppred[k + 1]
            out[k] = out[k] + G * G * (out[k + 1] - Ppred[k + 1])
    return np.array(out)


@pytest.mark.parametrize("offline", [False, True])
def test_kf_std_equals_an_independent_scalar_filter(offline):
    seq = _gappy(states=True)
    q, r = 0.002, (0.01, 0.02, 0.04)
    out = tk.smooth(seq, method="kf", q=q, r=r, offline=offline, inferred_noise_factor=4.0)
    for j in range(2):
        y = seq.positions[:, j, 0].copy()
        y[seq.tracking_state[:, j] == TrackingState.NOT_TRACKED] = np.nan
        scale = np.where(seq.tracking_state[:, j] == TrackingState.INFERRED, 4.0, 1.0)
        var = np.stack([_scalar_kf(y, q, ra, scale, offline) for ra in r])  # per axis
        want = np.sqrt(var.mean(axis=0))  # rms over the axes of the per-axis sd
        first = np.flatnonzero(~np.isnan(y))[0]
        want[:first] = np.nan  # no estimate before the first measurement
        np.testing.assert_allclose(out.std[:, j], want, rtol=1e-12, equal_nan=True)


def test_std_is_nan_exactly_where_there_is_no_estimate():
    out = tk.smooth(_gappy(), method="atkf")
    assert np.array_equal(np.isnan(out.std), out.sample_state == NONE)
    assert (out.std[out.sample_state != NONE] > 0).all()


# ---------------------------------------------------------------- provenance


def test_provenance_holds_version_method_and_complete_params():
    pyproject = (ROOT / "pyproject.toml").read_text()
    version = re.search(r'^version = "([^"]+)"', pyproject, re.MULTILINE).group(1)
    out = tk.smooth(_gappy(), method="atkf", q=0.003)
    prov = out.metadata["provenance"]
    assert prov["tobitkf_version"] == version == tk.__version__
    assert prov["method"] == "atkf"
    params = prov["params"]
    # every parameter of the method, the given one, the common keywords, and the fitted
    # half-widths: the paper's 0.34 m horizontal, 0.18 m vertical on the y (up) axis
    assert set(tk.method_defaults("atkf")) <= set(params)
    assert params["q"] == 0.003
    assert {"offline", "inferred_noise_factor", "up_axis"} <= set(params)
    assert tuple(params["c"]) == (0.34, 0.18, 0.34)
    assert params == out.metadata["diagnostics"]["params"]
    assert prov["source"] == {"path": "x.csv"}
    # smoothing again keeps the earlier provenance
    again = tk.smooth(out, method="kf")
    assert again.metadata["provenance"]["input"]["method"] == "atkf"


# ---------------------------------------------------------------- CSV


def test_pandas_reads_our_csv_with_no_options(tmp_path):
    seq = _gappy(states=True)
    out = tk.smooth(seq, method="kf", offline=True)
    p = tmp_path / "a.kf.csv"
    save(out, p)
    assert not p.read_text().startswith("#")
    df = pd.read_csv(p)  # no options
    for j, name in enumerate(out.joint_names):
        for a, axis in enumerate("xyz"):
            np.testing.assert_array_equal(df[f"{name}_{axis}"].to_numpy(), out.positions[:, j, a])
        np.testing.assert_array_equal(df[f"{name}_state"].to_numpy(), out.tracking_state[:, j])
        np.testing.assert_array_equal(df[f"{name}_sd"].to_numpy(), out.std[:, j])
        np.testing.assert_array_equal(df[f"{name}_sample"].to_numpy(), out.sample_state[:, j])
    assert len(df) == 10 and "time" not in df.columns  # fps only: no time column


def test_csv_sidecar_names_and_content(tmp_path):
    out = tk.smooth(_gappy(), method="kf", q=0.004)
    p = tmp_path / "a.kf.csv"
    save(out, p)
    side = tmp_path / "a.kf.json"
    assert sidecar_path(p) == side and side.is_file()
    doc = json.loads(side.read_text())
    assert doc["format"] == "tobitkf.csv-sidecar"
    assert (doc["topology"], doc["up_axis"], doc["fps"]) == ("pair", 1, 30.0)
    assert doc["provenance"]["method"] == "kf"
    assert doc["provenance"]["params"]["q"] == 0.004
    assert doc["provenance"]["tobitkf_version"] == tk.__version__
    # the sidecar carries fps, topology name, up axis and provenance through a round trip
    (back,) = load(p)
    assert back.fps == 30.0 and back.topology.name == "pair"
    assert back.metadata["provenance"]["params"]["q"] == 0.004
    # without it the table still reads, with what the table holds
    side.unlink()
    (bare,) = load(p)
    assert bare.fps is None and "provenance" not in bare.metadata
    np.testing.assert_array_equal(bare.positions, out.positions)


def test_csv_never_overwrites_a_foreign_json_and_ignores_it_when_reading(tmp_path):
    seq = _gappy()
    (tmp_path / "a.json").write_text('{"my": "notes", "fps": 99}')
    with pytest.raises(ValueError, match="not a tobitkf CSV sidecar"):
        write_csv([seq], tmp_path / "a.csv")
    assert json.loads((tmp_path / "a.json").read_text()) == {"my": "notes", "fps": 99}
    write_csv([seq], tmp_path / "a.csv", sidecar=False)
    (back,) = read_csv(tmp_path / "a.csv")
    assert back.fps is None  # the foreign JSON is not read as a sidecar
    np.testing.assert_array_equal(back.positions, seq.positions)


@pytest.mark.parametrize(
    ("entry", "match"),
    [
        ({"fps": "thirty"}, "expected a number for fps"),
        ({"fps": 1e9}, "implausible fps"),
        ({"up_axis": 5}, "up_axis 0, 1 or 2"),
        ({"bodies": {"a": 1}}, "list of bodies"),
        ({"bodies": [{"body": None, "body_id": 1.5}]}, "int or str body id"),
    ],
)
def test_a_bad_sidecar_is_a_read_error_naming_it(tmp_path, entry, match):
    p = tmp_path / "a.csv"
    write_csv([_gappy()], p)
    doc = json.loads(sidecar_path(p).read_text())
    sidecar_path(p).write_text(json.dumps({**doc, **entry}))
    with pytest.raises(tk.ReadError, match=match) as e:
        read_csv(p)
    assert "a.json" in str(e.value)


def test_csv_round_trip_of_std_and_sample_state(tmp_path):
    topo = get_topology("kinect_v2")
    a = tk.smooth(tk.generate_motion("arms", duration=1.0, seed=3), method="kf", offline=True)
    b = a.replace(body_id=8, std=None, sample_state=None)  # a body without them
    a = a.replace(body_id=7)
    p = tmp_path / "m.csv"
    save([a, b], p)
    back = load(p)
    assert [s.body_id for s in back] == [7, 8]
    np.testing.assert_array_equal(back[0].std, a.std)
    np.testing.assert_array_equal(back[0].sample_state, a.sample_state)
    assert back[1].std is None and back[1].sample_state is None
    assert back[0].topology == topo
    # one body
    save(a, p)
    (one,) = load(p)
    np.testing.assert_array_equal(one.std, a.std)
    np.testing.assert_array_equal(one.sample_state, a.sample_state)
    assert one.body_id == 7


def test_csv_old_layout_with_comment_lines_still_reads(tmp_path):
    p = tmp_path / "old.csv"
    p.write_text(
        "# topology: pair\n# fps: 25.0\n# up_axis: 2\n# body_id: 4\n"
        "time,a_x,a_y,a_z,a_state\n0.0,1,2,3,2\n0.04,1.5,,3,1\n"
    )
    (s,) = read_csv(p)
    assert (s.fps, s.topology.up_axis, s.body_id, s.topology.name) == (25.0, 2, 4, "pair")
    np.testing.assert_array_equal(s.tracking_state[:, 0], [2, 1])
    assert s.std is None and s.sample_state is None


def test_csv_written_by_pandas_with_its_index_column(tmp_path):
    rng = np.random.default_rng(1)
    vals = rng.normal(size=(5, 6))
    cols = ["a_x", "a_y", "a_z", "b_x", "b_y", "b_z"]
    df = pd.DataFrame(vals, columns=cols)
    df.loc[2, "b_y"] = np.nan
    p = tmp_path / "pd.csv"
    df.to_csv(p)  # index column with an empty header field
    assert p.read_text().startswith(",a_x")
    (s,) = load(p)
    np.testing.assert_array_equal(s.positions.reshape(5, 6), df.to_numpy())
    # a round trip through pandas names the index column "Unnamed: 0"
    again = tmp_path / "again.csv"
    pd.read_csv(p).to_csv(again, index=False)
    assert again.read_text().startswith("Unnamed: 0,")
    (s2,) = load(again)
    np.testing.assert_array_equal(s2.positions, s.positions)


# ---------------------------------------------------------------- NPZ and NTU


def test_npz_round_trip_of_std_sample_state_and_provenance(tmp_path):
    out = tk.smooth(_gappy(states=True), method="atkf", offline=True)
    p = tmp_path / "a.npz"
    write_npz([out], p)
    (back,) = read_npz(p)
    np.testing.assert_array_equal(back.std, out.std)
    np.testing.assert_array_equal(back.sample_state, out.sample_state)
    assert back.sample_state.dtype == np.int8
    prov = back.metadata["provenance"]
    assert prov == out.metadata["provenance"]
    assert prov["params"]["c"] == (0.34, 0.18, 0.34)  # the tuple stays a tuple


def test_ntu_marks_filled_joints_inferred(tmp_path):
    T = 12
    rng = np.random.default_rng(2)
    pos = np.array([0.0, 0.0, 2.5]) + rng.normal(scale=0.2, size=(T, 25, 3))
    seq = SkeletonSequence(pos, "kinect_v2", np.full((T, 25), 2, dtype=np.int8), fps=30.0,
                           body_id=5)  # fmt: skip
    src = tmp_path / "in.skeleton"
    write_ntu([seq], src)
    (raw,) = read_ntu(src)
    hand = raw.topology.index("HandRight")
    # the file says the hand was tracked at frames 4-6 but at (0, 0, 0): missing
    text = src.read_text().split("\n")
    body_lines = [i for i, ln in enumerate(text) if ln.startswith("5 ")]
    for f in (4, 5, 6):
        i = body_lines[f] + 2 + hand
        text[i] = " ".join(["0", "0", "0", *text[i].split()[3:]])
    src.write_text("\n".join(text))
    (raw,) = read_ntu(src)
    assert np.isnan(raw.positions[4:7, hand]).all()
    assert (raw.metadata["ntu_joint_state"][4:7, hand] == 2).all()  # as written in the file
    out = tk.smooth(raw, method="kf", offline=True)
    assert (out.sample_state[4:7, hand] == X).all()
    dst = tmp_path / "out.skeleton"
    write_ntu([out], dst)
    (back,) = read_ntu(dst)
    np.testing.assert_array_equal(back.positions[4:7, hand], out.positions[4:7, hand])
    assert (back.tracking_state[4:7, hand] == TrackingState.INFERRED).all()
    others = np.ones((T, 25), dtype=bool)
    others[4:7, hand] = False
    assert (back.tracking_state[others] == TrackingState.TRACKED).all()


def test_ntu_writes_joints_without_an_estimate_as_not_tracked(tmp_path):
    T = 4
    pos = np.full((T, 25, 3), 0.5)
    st = np.full((T, 25), 2, dtype=np.int8)
    sample = np.zeros((T, 25), dtype=np.int8)
    pos[0, 3] = np.nan
    sample[0, 3] = NONE
    seq = SkeletonSequence(pos, "kinect_v2", st, fps=30.0, body_id=1, sample_state=sample,
                           metadata={"ntu_joint_state": st})  # fmt: skip
    write_ntu([seq], tmp_path / "n.skeleton")
    (back,) = read_ntu(tmp_path / "n.skeleton")
    assert back.metadata["ntu_joint_state"][0, 3] == TrackingState.NOT_TRACKED


# ---------------------------------------------------------------- tobitkf smooth


def test_cli_smooth_writes_the_sidecar_with_provenance(tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    save(tk.generate_motion("arms", duration=1.0, seed=4), src / "rec.npz")
    out = tmp_path / "out"
    res = CliRunner().invoke(
        app, ["smooth", str(src / "rec.npz"), "-o", str(out), "-m", "kf", "-f", "csv",
              "-p", "q=0.005"],
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in out.iterdir()) == [
        "rec.kf.csv",
        "rec.kf.json",
        "tobitkf-manifest.jsonl",
    ]
    doc = json.loads((out / "rec.kf.json").read_text())
    assert doc["provenance"]["params"]["q"] == 0.005
    assert doc["provenance"]["source"]["path"] == str(src / "rec.npz")
    assert re.fullmatch(r"\d+\.\d+\.\d+.*", doc["provenance"]["tobitkf_version"])
    df = pd.read_csv(out / "rec.kf.csv")
    assert {"SpineBase_sd", "SpineBase_sample"} <= set(df.columns)


def test_batch_never_lets_a_sidecar_overwrite_an_input(tmp_path):
    rec = tmp_path / "x.csv"
    side_input = tmp_path / "x.kf.json"  # an input that is where x.csv's sidecar would go
    for f in (rec, side_input):
        f.write_text("a_x,a_y,a_z\n1,2,3\n")
    jobs, refused = plan_jobs(
        [(rec, tmp_path), (side_input, tmp_path)], tmp_path, method="kf", output_format="csv"
    )
    assert [j.source for j in jobs] == [side_input]
    assert len(refused) == 1 and "x.kf.json would overwrite an input" in refused[0].error

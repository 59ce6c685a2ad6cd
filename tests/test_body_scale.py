"""A recording said to be in metres whose size says otherwise, a magnitude no arithmetic
holds (smoothing/body_scale.py), and the unit a file does not state given by its user
(``--units``, io/unstated.py).

The radius is checked against bodies built with a known radius and against the exact
identities it must keep (scale, translation); the refusal on a real Kinect recording
put into millimetres and centimetres; a track declared in millimetres against the same
track in metres (the methods work in metres: the outputs must agree to rounding); the
command line on a CSV without its sidecar, with and without ``--units``.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

import tobitkf as tk
from conftest import data_file
from tobitkf.app.commands import app
from tobitkf.evaluation.synthetic import generate_motion
from tobitkf.io.unstated import states_no_units, with_unstated
from tobitkf.smoothing.body_scale import MAX_BODY_RADIUS_M, body_radius, check_body_scale

KERAAL = "keraal/G3-Kinect-CTK-P1T1-Unknown-C-0.txt"


def _star(r: float, centre=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Six joints at distance r from ``centre`` along the axes: radius r exactly."""
    offsets = np.vstack([np.eye(3), -np.eye(3)]) * r
    return offsets + np.asarray(centre)


def test_the_radius_of_a_body_built_with_one():
    frames = np.stack([_star(0.4, (1.0, 2.0, 3.0)), _star(0.2), _star(0.3)])  # (3, 6, 3)
    # per frame the mean distance is the star's r; over frames the median of 0.4, 0.2, 0.3
    assert body_radius(frames[:, None])[0] == pytest.approx(0.3, abs=1e-12)


def test_missing_joints_and_bodies_do_not_count():
    y = np.full((4, 2, 6, 3), np.nan)
    y[:, 0] = _star(0.5)
    y[1, 0, [0, 3]] = np.nan  # two opposite joints missing in one frame: the others still at 0.5
    y[2, 1, 0] = 1.0  # body 1: one joint in one frame, no frame of two
    r = body_radius(y)
    assert r[0] == pytest.approx(0.5, abs=1e-12)
    assert np.isnan(r[1])
    check_body_scale(y, metres=True)  # a body with no radius is not refused
    assert np.isnan(check_body_scale(np.zeros((0, 2, 6, 3)), metres=True)).all()  # no frame
    assert check_body_scale(np.zeros((3, 0, 6, 3)), metres=True).shape == (0,)  # no body


@settings(max_examples=40, deadline=None)
@given(
    k=st.floats(1e-3, 1e3),
    shift=st.lists(st.floats(-1e3, 1e3), min_size=3, max_size=3),
    seed=st.integers(0, 2**16),
)
def test_the_radius_scales_with_the_unit_and_ignores_where_the_body_is(k, shift, seed):
    rng = np.random.default_rng(seed)
    y = rng.normal(size=(7, 2, 9, 3))
    y[rng.random((7, 2, 9)) < 0.2] = np.nan
    r = body_radius(y)
    moved = body_radius(y * k + np.asarray(shift))
    np.testing.assert_allclose(moved, r * k, rtol=1e-9, atol=1e-9 * (1 + np.abs(shift).max()))


def test_a_person_in_metres_passes_and_in_mm_or_cm_is_refused_with_the_unit():
    seq = tk.load(data_file(KERAAL))[0]
    ys = seq.positions[:, None]
    r = check_body_scale(ys, metres=True)[0]
    assert 0.1 < r < 1.0  # a person: joints some decimetres from their centre
    for k, unit in ((1000.0, "millimetres"), (100.0, "centimetres")):
        with pytest.raises(ValueError, match=f"look like {unit}"):
            check_body_scale(ys * k, metres=True)
        check_body_scale(ys * k, metres=False)  # in unknown units: any size a body may have
    with pytest.raises(ValueError, match="are not metres"):
        check_body_scale(ys * 1e6, metres=True)
    assert MAX_BODY_RADIUS_M < 100 * r  # a person in centimetres is over the bound


@pytest.mark.parametrize("method", ["robust", "robust_online", "kf"])
def test_smooth_refuses_millimetres_taken_as_metres(method):
    seq = generate_motion("arms", duration=3.0, seed=1)
    with pytest.raises(ValueError, match=r"look like millimetres.*--units mm"):
        tk.smooth(seq.replace(positions=seq.positions * 1000), method=method)


@pytest.mark.parametrize("method", ["robust", "robust_online"])
def test_the_same_track_in_millimetres_gives_the_same_output(method):
    seq = generate_motion("mixed", duration=4.0, seed=2)
    metres = tk.smooth(seq, method=method)
    mm = tk.smooth(seq.replace(positions=seq.positions * 1000, units="mm"), method=method)
    # to 10 micrometres: the noise fit's optimiser sees the rounding of the conversion,
    # and the reweighting passes (weights from the pass before) pass it on
    np.testing.assert_allclose(mm.positions / 1000, metres.positions, rtol=0, atol=1e-5)


def test_live_refuses_millimetres_taken_as_metres_at_the_first_frame():
    seq = generate_motion("arms", duration=1.0, seed=3)
    live = tk.LiveSmoother(seq.topology)
    with pytest.raises(ValueError, match="look like millimetres"):
        live.update(seq.positions[0] * 1000)
    declared = tk.LiveSmoother(seq.topology, units="mm")
    metres = tk.LiveSmoother(seq.topology)
    for t in range(10):
        out_mm = declared.update(seq.positions[t] * 1000)
        out_m = metres.update(seq.positions[t])
    np.testing.assert_allclose(out_mm / 1000, out_m, rtol=0, atol=1e-9)


def _csv_in_mm(tmp_path, seq):
    """The track written in millimetres as a CSV without its sidecar (a unit unstated)."""
    path = tmp_path / "track.csv"
    tk.save(seq.replace(positions=seq.positions * 1000), path)
    path.with_suffix(".json").unlink()
    return path


def test_a_csv_without_sidecar_states_no_unit_and_units_gives_it(tmp_path):
    seq = generate_motion("arms", duration=1.0, seed=4)
    path = _csv_in_mm(tmp_path, seq)
    read = tk.load(path)
    assert read[0].units == "m" and states_no_units(read[0])  # metres assumed
    given_mm = with_unstated(read, units="mm")[0]
    assert given_mm.units == "mm" and not states_no_units(given_mm)
    tk.save(seq, tmp_path / "stated.csv")  # with its sidecar: metres stated, kept
    stated = tk.load(tmp_path / "stated.csv")
    assert not states_no_units(stated[0])
    assert with_unstated(stated, units="mm")[0].units == "m"


def test_the_command_line_refuses_then_smooths_with_units(tmp_path):
    seq = generate_motion("arms", duration=2.0, seed=5)
    path = _csv_in_mm(tmp_path, seq)
    runner = CliRunner()
    res = runner.invoke(app, ["smooth", str(path), "-o", str(tmp_path / "a"), "--fps", "30"])
    assert res.exit_code != 0
    assert "look like millimetres" in res.output
    assert not list((tmp_path / "a").glob("*.csv"))  # nothing written for it
    res = runner.invoke(
        app,
        ["smooth", str(path), "-o", str(tmp_path / "b"), "--fps", "30", "--units", "mm", "--json"],
    )
    assert res.exit_code == 0, res.output
    out = tk.load(next((tmp_path / "b").glob("*.csv")))[0]
    assert out.units == "mm"
    expected = tk.smooth(seq)  # the same track in metres, smoothed in Python
    np.testing.assert_allclose(out.positions / 1000, expected.positions, rtol=0, atol=1e-6)
    lines = (tmp_path / "b" / "tobitkf-manifest.jsonl").read_text().splitlines()
    settings = [json.loads(line) for line in lines]
    assert any(s.get("settings", s).get("params", {}).get("input_units") == "mm" for s in settings)


@pytest.mark.parametrize("k", [1e-150, 1e200])
@pytest.mark.parametrize("method", ["robust", "robust_online", "kf"])
def test_a_magnitude_no_arithmetic_holds_is_refused_in_any_unit(k, method):
    """At 1e-150 units robust returned NaN everywhere; at 1e200 it overflowed."""
    seq = generate_motion("arms", duration=2.0, seed=6)
    with pytest.raises(ValueError, match="arithmetic holds"):
        tk.smooth(seq.replace(positions=seq.positions * k, units=None), method=method)
    live = (
        tk.LiveSmoother(seq.topology, method, units=None, gates_from="stream")
        if method == "robust_online"  # unknown units live: the gates from the stream
        else tk.LiveSmoother(seq.topology, "kf")  # robust does not run live
    )
    with pytest.raises(ValueError, match="arithmetic holds"):
        live.update(seq.positions[0] * k)


@pytest.mark.parametrize("k", [1e-40, 1e40])
def test_inside_the_bounds_the_robust_output_scales_with_the_data(k):
    """Unknown units: the gates and the noise come from the recording, so the output of
    the data times k is the output times k (to the noise fit's optimiser tolerance)."""
    seq = generate_motion("mixed", duration=3.0, seed=7).replace(units=None)
    for method, tol in (("robust", 1e-5), ("robust_online", 1e-12)):
        base = tk.smooth(seq, method=method)
        out = tk.smooth(seq.replace(positions=seq.positions * k), method=method)
        assert np.isfinite(out.positions).all()
        np.testing.assert_allclose(out.positions / k, base.positions, rtol=0, atol=tol)


def test_an_array_states_no_unit_unless_given(tmp_path):
    seq = generate_motion("arms", duration=1.0, seed=8)
    np.save(tmp_path / "a.npy", seq.positions * 1000)
    read = tk.load(tmp_path / "a.npy", topology="kinect_v2", fps=30)[0]
    assert read.units is None and states_no_units(read)
    assert with_unstated([read], units="mm")[0].units == "mm"
    given = tk.load(tmp_path / "a.npy", topology="kinect_v2", fps=30, units="mm")[0]
    assert given.units == "mm" and not states_no_units(given)


def test_evaluate_takes_the_unit_of_a_track_that_states_none(tmp_path):
    seq = generate_motion("arms", duration=2.0, seed=9)
    path = _csv_in_mm(tmp_path, seq)
    runner = CliRunner()
    args = ["evaluate", str(path), "--fps", "30", "--methods", "robust", "--json"]
    res = runner.invoke(app, args)
    assert res.exit_code != 0 and "look like millimetres" in res.output
    res = runner.invoke(app, [*args, "--units", "mm"])
    assert res.exit_code == 0, res.output


def test_gates_measured_on_the_recording_take_any_size_in_metres():
    """With gates="recording" no physical constant is used: a track in millimetres taken
    as metres is smoothed as the same track in metres (the gates scale with the data)."""
    seq = generate_motion("mixed", duration=3.0, seed=10)
    metres = tk.smooth(seq, method="robust", gates="recording")
    mm = tk.smooth(seq.replace(positions=seq.positions * 1000), method="robust", gates="recording")
    np.testing.assert_allclose(mm.positions / 1000, metres.positions, rtol=0, atol=1e-6)


def test_info_says_the_unit_is_assumed_and_the_size_wrong(tmp_path):
    from tobitkf.app.info import describe

    seq = generate_motion("arms", duration=1.0, seed=11)
    body = describe(_csv_in_mm(tmp_path, seq))["sequences"][0]
    assert body["units"] == "m" and not body["units_stated"]
    assert "look like millimetres" in body["size_problem"]
    res = CliRunner().invoke(app, ["info", str(tmp_path / "track.csv")])
    assert res.exit_code == 0 and "states none" in res.output
    tk.save(seq, tmp_path / "stated.csv")
    body = describe(tmp_path / "stated.csv")["sequences"][0]
    assert body["units_stated"] and "size_problem" not in body


def test_info_names_the_unit_a_3d_array_of_a_persons_size_looks_like(tmp_path):
    from tobitkf.app.info import describe

    seq = generate_motion("arms", duration=1.0, seed=11)  # a person, in metres
    for k, unit in ((1.0, "units='m'"), (100.0, "units='cm'")):
        np.save(tmp_path / "track.npy", seq.positions * k)
        body = describe(tmp_path / "track.npy")["sequences"][0]
        assert body["units"] is None and unit in body["size_note"]
    np.save(tmp_path / "flat.npy", seq.positions[..., :2])  # 2-D: image keypoints
    assert "size_note" not in describe(tmp_path / "flat.npy")["sequences"][0]
    res = CliRunner().invoke(app, ["info", str(tmp_path / "track.npy")])
    assert res.exit_code == 0 and "--units cm" in " ".join(res.output.split())
    body = describe(_csv_in_mm(tmp_path, seq))["sequences"][0]  # a unit assumed: no note
    assert "size_note" not in body


def test_a_single_point_is_judged_by_its_motion_and_a_still_one_is_left_alone():
    rng = np.random.default_rng(12)
    point = np.cumsum(rng.normal(0, 0.01, (50, 1, 3)), axis=0)  # one marker, moving
    topo = tk.Topology.from_names(["m"])
    out = tk.smooth(tk.SkeletonSequence(positions=point, topology=topo, fps=30.0))
    assert np.isfinite(out.positions).all()
    still = tk.smooth(tk.SkeletonSequence(positions=np.zeros((20, 2, 3)), fps=30.0,
                                          topology=tk.Topology.from_names(["a", "b"])))  # fmt: skip
    np.testing.assert_array_equal(still.positions, 0.0)
    with pytest.raises(ValueError, match="spreads 4"):
        tk.smooth(tk.SkeletonSequence(positions=point * 1e-150, topology=topo, fps=30.0))
    with pytest.raises(ValueError, match="reaches"):
        tk.smooth(tk.SkeletonSequence(positions=point + 1e60, topology=topo, fps=30.0))


@pytest.mark.parametrize("method", ["robust", "robust_online", "kf"])
def test_a_lone_huge_sample_is_a_glitch_not_a_refusal(method):
    """The size is read on 16 frames spread over the recording; a single 1e200 sample in
    another frame is a glitch: the output stays finite (and robust rejects it)."""
    seq = generate_motion("arms", duration=4.0, seed=13)
    sampled = np.linspace(0, seq.n_frames - 1, 16).round().astype(int)
    frame = next(f for f in range(50, 60) if f not in sampled)
    pos = seq.positions.copy()
    pos[frame, 7, 0] = 1e200
    out = tk.smooth(seq.replace(positions=pos), method=method)
    assert np.isfinite(out.positions).all()
    if method.startswith("robust"):
        assert out.metadata["diagnostics"]["rejected"][frame, 7]
        assert np.abs(out.positions).max() < 10.0


def test_an_npz_states_the_unit_its_source_csv_did_not(tmp_path):
    """Read from a CSV without its sidecar (metres assumed), smoothed and saved as NPZ:
    the NPZ states its unit, so --units does not apply to it."""
    seq = generate_motion("arms", duration=1.0, seed=14)
    tk.save(seq, tmp_path / "a.csv")
    (tmp_path / "a.json").unlink()
    read = tk.load(tmp_path / "a.csv")[0]
    assert states_no_units(read)
    tk.save(tk.smooth(read), tmp_path / "b.npz")
    back = tk.load(tmp_path / "b.npz")[0]
    assert back.units == "m" and not states_no_units(back)
    assert with_unstated([back], units="mm")[0].units == "m"


def test_the_delayed_smoother_refuses_at_its_first_run():
    """DelayedSmoother runs the batch method on its window from ``delay`` after the first
    frame on: a track in millimetres taken as metres is refused there, with the reason."""
    seq = generate_motion("arms", duration=2.0, seed=15)
    d = tk.DelayedSmoother(seq.topology, delay=0.5)
    with pytest.raises(ValueError, match="look like millimetres"):
        for t in range(seq.n_frames):
            d.update(seq.positions[t] * 1000)
    assert t == round(0.5 * 30)  # the frame of its first run


@pytest.mark.parametrize(
    "radius, unit",
    [
        (0.4, "m"),
        (0.4 * 10**0.49, "m"),  # within half a decade of a person's size in metres
        (40.0, "cm"),
        (400.0, "mm"),
        (0.4 * 10**-0.49, "m"),
        (0.4 * 10**0.51, None),  # between metres and centimetres: no unit told
        (0.4 * 10**1.51, "cm"),  # within half a decade of it in centimetres
        (0.4 * 10**1.49, None),
        (0.4 * 10**3.51, None),  # beyond millimetres
        (0.01, None),  # a hand's or a mouse's size in metres: not a person's in any
        (float("nan"), None),
        (0.0, None),
    ],
)
def test_the_unit_a_persons_size_tells(radius, unit):
    from tobitkf.smoothing.body_scale import person_unit

    got = person_unit(radius)
    assert (got[1] if got else None) == unit


def _unit_warnings(positions, **kw) -> list[str]:
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        tk.smooth(positions, fps=30.0, topology="kinect_v2", **kw)
    return [str(w.message) for w in caught if "state no length unit" in str(w.message)]


def test_an_array_of_a_persons_size_in_no_unit_is_smoothed_with_a_warning_naming_it():
    # 25 joints on a star of radius 0.4 (the rest at the centre's star too): a person in m
    T = 40
    star = np.vstack([_star(0.4)] * 5)[:25]  # every joint 0.4 from the centre
    y = np.broadcast_to(star, (T, 25, 3)) + 0.002 * np.random.default_rng(0).normal(size=(T, 25, 3))
    said = _unit_warnings(y)
    assert len(said) == 1 and "units='m'" in said[0] and "--units m " in said[0]
    said = _unit_warnings(y * 100)
    assert len(said) == 1 and "units='cm'" in said[0]
    assert _unit_warnings(y, units="m") == []  # declared
    assert _unit_warnings(y[..., :2]) == []  # 2-D: image keypoints, no person's size in m
    assert _unit_warnings(y * 5) == []  # a size like no person's in m, cm or mm
    assert _unit_warnings(y, gates="recording") == []  # asked for the recording's gates


def test_the_command_line_warns_on_an_array_of_a_persons_size_without_units(tmp_path):
    seq = tk.load(data_file(KERAAL))[0]
    np.save(tmp_path / "track.npy", seq.positions)
    args = ["smooth", str(tmp_path / "track.npy"), "--fps", "30", "--topology", "kinect_v2"]
    res = CliRunner().invoke(app, [*args, "-o", str(tmp_path / "a")])
    assert res.exit_code == 0, res.output
    assert "state no length unit" in res.output and "--units m " in res.output
    res = CliRunner().invoke(app, [*args, "--units", "m", "-o", str(tmp_path / "b")])
    assert res.exit_code == 0, res.output
    assert "state no length unit" not in res.output

"""The smoothing policy, rule by rule, on sequences whose right answer is known by hand.

Every test here states one documented rule (docs/robust.md, the docstrings of the robust
smoother, of ``smooth`` and of the Tobit filters) and checks it on a small synthetic
sequence whose expected result was derived from the rule itself (the frame numbers in
the comments), not read off the code's output.  Each test fails when its rule is removed
or changed (docs/mutation.md: mutation testing by hand).

Only the public API is used (``import tobitkf as tk``), so the tests survive a re-layout
of the package's modules.

Conventions: 30 fps without timestamps, so frame k is at k/30 s; the speed gate after
k frames is ``v_max * k / 30 + margin``.  Expected frame sets avoid the boundaries of
every rule (no ``time == min_run`` comparisons, which would depend on rounding).
"""

from __future__ import annotations

import functools
import importlib
import math

import numpy as np
import pytest
from scipy import special
from scipy.linalg import expm

import tobitkf as tk

FPS = 30.0
DT = 1.0 / FPS
TRACKED = int(tk.TrackingState.TRACKED)
INFERRED = int(tk.TrackingState.INFERRED)
NOT_TRACKED = int(tk.TrackingState.NOT_TRACKED)
ROBUST = ("robust", "robust_online")

# a bent right arm: shoulder (root), elbow 0.3 m to the side, wrist 0.25 m below the elbow
SHOULDER = np.array([0.0, 1.0, 2.0])
ELBOW = SHOULDER + np.array([0.3, 0.0, 0.0])
WRIST = ELBOW + np.array([0.0, -0.25, 0.0])
OFF = np.array([0.0, 0.3, 0.0])  # breaks the elbow's bone: |(0.3, 0.3)| = 0.42 vs 0.3


# ----------------------------------------------------------------------------- helpers
def _point(T: int, x: float = 0.0) -> np.ndarray:
    """One root joint (no bone) standing still at (x, 1, 2): positions (T, 1, 3)."""
    pos = np.zeros((T, 1, 3)) + np.array([0.0, 1.0, 2.0])
    pos[:, 0, 0] = x
    return pos


def _arm(T: int, joints: int = 3) -> np.ndarray:
    """The still arm (shoulder, elbow, wrist)[:joints]: positions (T, joints, 3)."""
    return np.broadcast_to(np.stack([SHOULDER, ELBOW, WRIST])[:joints], (T, joints, 3)).copy()


def _seq(pos, states=None, timestamps=None) -> tk.SkeletonSequence:
    J = pos.shape[1]
    if J == 1:
        topo = tk.Topology.from_names(["SpineBase"])
    else:
        names = ["ShoulderRight", "ElbowRight", "WristRight"][:J]
        topo = tk.Topology.from_names(names, parents=[-1, 0, 1][:J])
    kw = {"timestamps": timestamps} if timestamps is not None else {"fps": FPS}
    return tk.SkeletonSequence(positions=pos, topology=topo, tracking_state=states, **kw)


def _run(pos, method, states=None, **params):
    out = tk.smooth(_seq(pos, states), method, **params)
    return out.positions, out.metadata["diagnostics"]["rejected"]


def _frames(mask) -> list[int]:
    return np.flatnonzero(mask).tolist()


def _span(a: int, b: int) -> list[int]:
    """Frames a..b inclusive."""
    return list(range(a, b + 1))


# ----------------------------------------------------------------------------- speed gate
@pytest.mark.parametrize("method", ROBUST)
def test_a_one_metre_jump_for_five_frames_is_rejected_and_bridged(method):
    # v_max 3 m/s: the gate after k <= 5 frames is at most 0.1 k + 0.05 = 0.55 m < 1 m, so
    # frames 15-19 are rejected; frame 20 is back where it was (distance 0).  Online, the
    # 5-frame rejection (>= min_run 0.09 s) makes frames 20-22 wait for confirmation
    # (0, 1/30, 2/30 s < 0.09 s after the return); frame 23 (0.1 s) is believed again.
    pos = _point(40)
    pos[15:20, 0, 0] += 1.0
    est, rej = _run(pos, method, v_max=3.0, min_run=0.09)
    assert _frames(rej[:, 0]) == (_span(15, 19) if method == "robust" else _span(15, 22))
    # the joint never moved: the failure is bridged (offline) or held (online) exactly
    np.testing.assert_allclose(est, _point(40), rtol=0, atol=1e-9)


@pytest.mark.parametrize("method", ROBUST)
@pytest.mark.parametrize("margin", [0.05, 0.02])
def test_speed_gate_is_v_max_times_dt_plus_margin(method, margin):
    # v_max 1 m/s: one frame may move 1/30 m + margin.  A one-frame excursion 5 mm inside
    # the gate is accepted, one 5 mm outside it is rejected (and only that frame: the
    # next one is back at the old place).
    gate = 1.0 * DT + margin
    for step, expected in ((gate - 0.005, []), (gate + 0.005, [10])):
        pos = _point(30)
        pos[10, 0, 0] += step
        _, rej = _run(pos, method, v_max=1.0, margin=margin)
        assert _frames(rej[:, 0]) == expected, (step, gate)


@pytest.mark.parametrize("method", ROBUST)
def test_speed_gate_grows_with_the_time_since_the_last_accepted_sample(method):
    # a real step of 0.24 m at frame 20 with v_max 1 m/s, margin 0.05 m: the gate after k
    # frames is k/30 + 0.05 >= 0.24 first for k = 6 (5.7), so frames 20-24 are rejected
    # and frame 25 is accepted: the joint is picked up again instead of being lost.
    pos = _point(60)
    pos[20:, 0, 0] += 0.24
    params = {"v_max": 1.0, "margin": 0.05, "min_run": 0.0}
    if method == "robust":
        params["two_pass"] = False  # forward pass only
    _, rej = _run(pos, method, **params)
    assert _frames(rej[:, 0]) == _span(20, 24)


def test_offline_rejects_what_either_pass_rejects():
    # the step above: forward rejects 20-24 (the new place); backward, coming from the
    # end, rejects 19, 18, ... down to 15 (k = 1..5 frames from frame 20) and accepts 14.
    # A sample is rejected when either pass rejects it: 15-24.
    pos = _point(60)
    pos[20:, 0, 0] += 0.24
    _, rej = _run(pos, "robust", v_max=1.0, margin=0.05)
    assert _frames(rej[:, 0]) == _span(15, 24)


# ----------------------------------------------------------------------------- bone gate
@pytest.mark.parametrize("method", ROBUST)
@pytest.mark.parametrize(
    ("tol_abs", "tol_rel", "inside", "outside"),
    [
        (0.03, 0.15, 0.070, 0.080),  # tolerance 0.03 + 0.15 * 0.3 = 0.075 m (the defaults)
        (0.0, 0.20, 0.055, 0.065),  # 0.06 m: relative part only
        (0.04, 0.0, 0.035, 0.045),  # 0.04 m: absolute part only
    ],
)
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_bone_gate_tolerance_is_abs_plus_rel_times_length(
    method, tol_abs, tol_rel, inside, outside, sign
):
    # shoulder (root) and elbow, bone 0.3 m (the median over the recording, and over the
    # frames seen so far online).  Frames 40-59 stretch (sign +1) or shorten (-1) the bone
    # by `inside` (accepted) or `outside` (rejected) metres; the speed gate (v_max 10)
    # lets both through.  A wrong bone is blamed on the distal joint, never the root.
    for change, expected in ((inside, []), (outside, _span(40, 59))):
        pos = _arm(100, joints=2)
        pos[40:60, 1, 0] += sign * change
        est, rej = _run(
            pos,
            method,
            v_max=10.0,
            bone_tol_abs=tol_abs,
            bone_tol_rel=tol_rel,
            min_run=0.0,
        )
        assert _frames(rej[:, 0]) == []
        assert _frames(rej[:, 1]) == expected, change
        if expected:  # carried with the shoulder: exactly where the elbow really is
            np.testing.assert_allclose(est, _arm(100, joints=2), rtol=0, atol=1e-9)


def test_bone_gate_is_off_with_bones_false():
    pos = _arm(100, joints=2)
    pos[40:60, 1, 0] += 0.08  # outside the default tolerance of 0.075 m
    _, rej = _run(pos, "robust", v_max=10.0)
    assert _frames(rej[:, 1]) == _span(40, 59)
    _, rej = _run(pos, "robust", v_max=10.0, bones=False)
    assert not rej.any()


# ----------------------------------------------------------------------------- chain rule
@pytest.mark.parametrize("method", ROBUST)
def test_child_that_jumped_with_a_rejected_parent_stays_rejected_until_it_returns(method):
    # elbow and wrist are reported 0.3 m too high together in frames 20-49.  The elbow's
    # bone breaks (0.42 m vs 0.3), so it is rejected; the wrist's bone is intact, and the
    # speed gate alone would admit it from frame 22 on (3 * 3/30 + 0.05 = 0.35 >= 0.3).
    # Chain rule: its parent is rejected and it jumped (0.3 > 0.15), so it is rejected,
    # and stays so (not accepted in the previous frame) until the elbow is back at 50.
    # Online, both then wait for confirmation in 50-52 (min_run 0.09 s).
    pos = _arm(80)
    pos[20:50, 1:] += OFF
    est, rej = _run(pos, method, v_max=3.0, min_run=0.09)
    end = 49 if method == "robust" else 52
    assert _frames(rej[:, 0]) == []
    assert _frames(rej[:, 1]) == _span(20, end)
    assert _frames(rej[:, 2]) == _span(20, end)
    np.testing.assert_allclose(est, _arm(80), rtol=0, atol=1e-9)  # carried, not followed


@pytest.mark.parametrize("method", ROBUST)
def test_child_that_stayed_put_beside_a_rejected_parent_is_kept(method):
    # only the elbow fails (frames 20-49); the wrist was accepted in the previous frame
    # and did not move, so the chain rule keeps it, although its bone to the (wrong)
    # measured elbow is broken.
    pos = _arm(80)
    pos[20:50, 1] += OFF
    _, rej = _run(pos, method, v_max=3.0, min_run=0.09)
    end = 49 if method == "robust" else 52
    assert _frames(rej[:, 1]) == _span(20, end)
    assert _frames(rej[:, 2]) == []


@pytest.mark.parametrize("method", ROBUST)
def test_chain_rule_is_applied_again_to_the_final_mask(method):
    # elbow fails in 30-39 and 42-51 (bone broken) with two good frames 40-41 between;
    # the wrist stays in place except for a 0.5 m spike at frame 39.  (Online the bone
    # gate needs 15 accepted frames to learn the length: it has 30.)
    # Gates: wrist 39 is rejected (parent rejected, it jumped).  Forwards, the wrist is
    #   accepted again at 40 beside the accepted elbow; backwards the chain rule rejects
    #   it in 30-39 (its parent rejected and frame 39 rejected).
    # Offline: the elbow's run 40-41 (1/30 s < min_run 0.09 s) is dropped, which leaves
    #   the wrist accepted in 40-51 beside a rejected elbow, having entered from a
    #   rejected frame.  The chain rule on the combined mask rejects it: wrist 30-51.
    # Online: the elbow's return at 40 waits for confirmation (after 10 rejected
    #   frames), is rejected again at 42-51, and waits again in 52-54; the wrist's own
    #   rejection (one frame) needs none, but its parent is rejected from 40 to 54 and it
    #   comes from a rejected frame: the forward chain rule rejects it in 39-54.
    pos = _arm(80)
    pos[30:40, 1] += OFF
    pos[42:52, 1] += OFF
    pos[39, 2] += [0.5, 0.0, 0.0]
    _, rej = _run(pos, method, v_max=3.0, min_run=0.09)
    if method == "robust":
        assert _frames(rej[:, 1]) == _span(30, 51)
        assert _frames(rej[:, 2]) == _span(30, 51)
    else:
        assert _frames(rej[:, 1]) == _span(30, 54)
        assert _frames(rej[:, 2]) == _span(39, 54)


def _chain_violations(seq, out, backward: bool) -> list[tuple[int, int]]:
    """(joint, frame) where an accepted joint has a rejected or missing parent without
    being accepted, and not having jumped, in the previous (and, if `backward`, the
    next) frame: the chain rule stated on the final mask."""
    d = out.metadata["diagnostics"]
    ys = seq.positions
    missing = np.isnan(ys).any(axis=-1)
    if seq.tracking_state is not None:
        missing |= seq.tracking_state == NOT_TRACKED
    acc = ~d["rejected"] & ~missing
    ts = seq.timestamps if seq.timestamps is not None else np.arange(seq.n_frames) * DT
    vmax, margin = np.asarray(d["params"]["v_max"]), d["params"]["margin"]
    T, bad = seq.n_frames, []
    for j, p in enumerate(seq.topology.parents):
        if p < 0:
            continue
        for t in np.flatnonzero(acc[:, j] & ~acc[:, p]):
            for s in (t - 1, t + 1) if backward else (t - 1,):
                if not 0 <= s < T:
                    continue
                bound = vmax[j] * abs(ts[t] - ts[s]) + margin
                if not (acc[s, j] and np.linalg.norm(ys[t, j] - ys[s, j]) <= bound):
                    bad.append((j, int(t)))
    return bad


@pytest.mark.parametrize(("method", "seeds"), [("robust", (1, 6)), ("robust_online", (1, 5))])
def test_final_mask_obeys_the_chain_rule_on_corrupted_motion(method, seeds):
    # the Kinect-like corruption model (sustained failures, spikes, dropped frames); the
    # seeds are ones where the per-pass gates alone leave orphans in the final mask
    for seed in seeds:
        seq = tk.corrupt(tk.generate_motion("mixed", duration=10.0, seed=seed), seed=seed)
        seq = seq.sequence
        out = tk.smooth(seq, method)
        assert out.metadata["diagnostics"]["rejected"].any()
        assert _chain_violations(seq, out, backward=method == "robust") == []


# ----------------------------------------------------------------------------- min_run
@pytest.mark.parametrize("gap", [False, True])
def test_offline_short_accepted_runs_between_rejections_are_rejected(gap):
    # elbow: good 0-1, fails 2-11, good 12-14 (3 frames, 2/30 s), fails 15-24, good 25-28
    # (4 frames, 3/30 s), fails 29-38, good from 39.  With min_run 0.08 s the 3-frame run
    # is rejected, the 4-frame run kept; the 2-frame run at the start is not *between*
    # two rejections and is kept.  With `gap`, frame 15 is missing: the run's neighbour
    # is then the next non-missing sample (16, rejected), and missing is not rejected.
    pos = _arm(70, joints=2)
    for a, b in ((2, 11), (15, 24), (29, 38)):
        pos[a : b + 1, 1] += OFF
    if gap:
        pos[15, 1] = np.nan
    fails = _span(2, 11) + _span(15, 24) + _span(29, 38)
    if gap:
        fails.remove(15)
    _, rej = _run(pos, "robust", v_max=3.0, min_run=0.0)
    assert _frames(rej[:, 1]) == fails
    _, rej = _run(pos, "robust", v_max=3.0, min_run=0.08)
    assert _frames(rej[:, 1]) == sorted([*fails, 12, 13, 14])
    _, rej = _run(pos, "robust", v_max=3.0, min_run=0.12)
    assert _frames(rej[:, 1]) == sorted([*fails, 12, 13, 14, 25, 26, 27, 28])


def test_online_waits_min_run_after_a_long_rejection_only():
    # elbow fails in 20-21 (2 frames: 2/30 s < min_run 0.09 s) and in 40-42 (3 frames:
    # 0.1 s >= 0.09 s).  After the short failure it is believed at once (22); after the
    # long one it waits until it has passed the gates for 0.09 s: 43, 44, 45 (0, 1/30,
    # 2/30 s) stay rejected, 46 is accepted.  Offline has no waiting.
    pos = _arm(70, joints=2)
    pos[20:22, 1] += OFF
    pos[40:43, 1] += OFF
    _, rej = _run(pos, "robust_online", v_max=3.0, min_run=0.09)
    assert _frames(rej[:, 1]) == [20, 21, *_span(40, 45)]
    _, rej = _run(pos, "robust_online", v_max=3.0, min_run=0.0)
    assert _frames(rej[:, 1]) == [20, 21, *_span(40, 42)]
    _, rej = _run(pos, "robust", v_max=3.0, min_run=0.09)
    assert _frames(rej[:, 1]) == [20, 21, *_span(40, 42)]


# ----------------------------------------------------------------------------- max_reject
@pytest.mark.parametrize("method", ROBUST)
def test_reacquired_after_max_reject_once_it_moves_plausibly(method):
    # a wrong start: frames 0-9 at x = 1 m, the true place x = 0 from frame 10.  With
    # v_max 0.5 m/s and margin 0.01 m the speed gate reaches 1 m only after 59.4 frames
    # (frame 69).  max_reject 0.95 s: from frame 39 on (29/30 s > 0.95 s since the
    # rejection began at 10) the joint is re-acquired, because it moves plausibly from
    # the previous frame (0 m <= 0.5/30 + 0.01 m).
    # Variant: in 10-49 it jumps 0.2 m every frame (implausible); it is re-acquired at
    # the first plausible step, frame 51 (50 still jumped from 49).
    params = {"v_max": 0.5, "margin": 0.01, "max_reject": 0.95, "min_run": 0.0}
    if method == "robust":
        params["two_pass"] = False
    pos = _point(80)
    pos[:10, 0, 0] = 1.0
    _, rej = _run(pos, method, **params)
    assert _frames(rej[:, 0]) == _span(10, 38)
    pos[11:50:2, 0, 0] = 0.2
    _, rej = _run(pos, method, **params)
    assert _frames(rej[:, 0]) == _span(10, 50)


# ----------------------------------------------------------------------------- lookback
def test_online_lookback_drops_the_entry_of_a_failure_from_the_state():
    # still at 0 for frames 0-19, a gradual failure entry 20: +5 cm, 21: +10 cm (both
    # pass the gate, 0.1 + 0.05 m per frame at v_max 3), then +1 m in 22-29 (rejected).
    # lookback 2: at 22 the state drops frames 20-21 and is re-predicted from frame 19,
    # where it was exactly (0, velocity 0): the output in 22-29 is exactly 0.  With
    # lookback 1 it keeps frame 20 (> 0), with 0 both (larger).  Outputs already emitted
    # (0-21) do not change.
    pos = _point(40)
    pos[20, 0, 0] = 0.05
    pos[21, 0, 0] = 0.10
    pos[22:30, 0, 0] = 1.0
    x = {}
    for lb in (0, 1, 2):
        est, rej = _run(pos, "robust_online", v_max=3.0, lookback=lb)
        assert _frames(rej[:22, 0]) == [] and rej[22:30, 0].all()
        x[lb] = est[:, 0, 0]
    np.testing.assert_allclose(x[2][22:30], 0.0, rtol=0, atol=1e-12)
    assert np.all(x[1][22:30] > 0.005)
    assert np.all(x[0][22:30] > x[1][22:30] + 0.005)
    np.testing.assert_array_equal(x[0][:22], x[2][:22])
    np.testing.assert_array_equal(x[1][:22], x[2][:22])
    assert x[2][21] > 0.05  # the entry itself was followed when it was emitted


def test_online_lookback_does_not_act_on_missing_frames():
    # a joint moving steadily at 0.3 m/s, occluded in frames 25-31; nothing is rejected,
    # so `lookback` must not change anything (the prediction must not move backwards)
    pos = _point(40)
    pos[:, 0, 0] = 0.01 * np.arange(40)
    pos[25:32] = np.nan
    a, rej = _run(pos, "robust_online", lookback=0)
    b, _ = _run(pos, "robust_online", lookback=2)
    assert not rej.any()
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


# ----------------------------------------------------------------------------- carrying
def test_carried_joint_follows_its_parent_online_exactly():
    # the shoulder sways, the elbow hangs 0.3 m beside it; the elbow is reported 0.3 m too
    # high in frames 30-49 (rejected; online it waits for confirmation in 50-52).
    # Documented filter: per axis an OU-velocity Kalman filter; a rejected joint gets a
    # pseudo-measurement at its parent's measured position plus its last good offset,
    # with standard deviation = that offset's length; lookback 2 at the rejection onset.
    T = 70
    rng = np.random.default_rng(0)
    t = np.arange(T) * DT
    pos = _arm(T, joints=2)
    pos += (0.2 * np.sin(np.pi * t))[:, None, None] * np.array([1.0, 0.3, -0.5])
    pos += rng.normal(scale=0.003, size=pos.shape)
    meas = pos.copy()
    meas[30:50, 1] += OFF
    kw = {"v_max": 5.0, "speed_sd": 0.6, "noise_sd": 0.01, "tau": 0.15, "min_run": 0.09}
    est, rej = _run(meas, "robust_online", **kw)
    assert _frames(rej[:, 0]) == [] and _frames(rej[:, 1]) == _span(30, 52)
    q = 2 * 0.6**2 / 0.15
    ok = ~rej[:, 1]
    offset = pos[29, 1] - pos[29, 0]  # the last frame both were accepted
    y = np.where(ok[:, None], meas[:, 1], pos[:, 0] + offset)
    r = np.where(ok, 0.01**2, offset @ offset)
    ref = _ref_guard(meas[:, 1], _ref_filter(y, r, t, 0.15, q, ok=ok, lookback=2))
    np.testing.assert_allclose(est[:, 1], ref, rtol=0, atol=1e-9)
    ref0 = _ref_guard(meas[:, 0], _ref_filter(pos[:, 0], np.full(T, 0.01**2), t, 0.15, q))
    np.testing.assert_allclose(est[:, 0], ref0, rtol=0, atol=1e-9)
    # without carrying, the elbow is only predicted by its own motion model: worse
    held, _ = _run(meas, "robust_online", carry=False, **kw)
    err = np.abs(est[30:53, 1] - pos[30:53, 1]).max()
    assert err < 0.5 * np.abs(held[30:53, 1] - pos[30:53, 1]).max()


def test_carried_joint_follows_its_parent_offline_exactly():
    # the same arm offline: the RTS bridge of the elbow is fed the same pseudo-
    # measurements (parent + offset, standard deviation = the offset's length), each
    # with its variance times the samples per tau (tau / dt = 4.5 here: consecutive
    # carried samples share one error, so a run of them counts as about one per tau)
    T = 70
    t = np.arange(T) * DT
    pos = _arm(T, joints=2)
    pos += (0.2 * np.sin(np.pi * t))[:, None, None] * np.array([1.0, 0.3, -0.5])
    meas = pos.copy()
    meas[30:50, 1] += OFF
    est, rej = _run(meas, "robust", v_max=5.0, noise="fixed", reweight=0)
    assert _frames(rej[:, 1]) == _span(30, 49)
    q = 2 * 0.6**2 / 0.15  # arms: speed_sd 0.6 m/s, noise_sd 10 mm; tau 0.15 s
    offset = pos[29, 1] - pos[29, 0]
    ok = ~rej[:, 1]
    y = np.where(ok[:, None], meas[:, 1], pos[:, 0] + offset)
    r = np.where(ok, 0.01**2, offset @ offset * (0.15 / DT))
    ref = _ref_filter(y, r, t, 0.15, q, smooth=True)
    np.testing.assert_allclose(est[:, 1], ref, rtol=0, atol=1e-9)
    held, _ = _run(meas, "robust", v_max=5.0, carry=False, noise="fixed")
    err = np.linalg.norm(est[30:50, 1] - pos[30:50, 1], axis=-1).max()
    err_held = np.linalg.norm(held[30:50, 1] - pos[30:50, 1], axis=-1).max()
    assert err < 0.95 * err_held


def test_carried_samples_count_once_per_tau():
    from tobitkf.smoothing._robust_kernels import carried_count

    assert carried_count(0.15, 1.0 / 30) == pytest.approx(4.5)
    assert carried_count(0.15, 0.5) == 1.0  # a step longer than tau: each counts
    assert carried_count(math.inf, 1.0 / 30) == 1.0  # no time scale: as before
    assert carried_count(0.15, 0.0) == 1.0


# ----------------------------------------------------------------------------- the filter
@functools.lru_cache(maxsize=4096)
def _ou_step(dt: float, tau: float) -> tuple[np.ndarray, np.ndarray]:
    """Transition and unit-q noise of dv = -v/tau dt + dW, dx = v dt (Van Loan)."""
    F = np.array([[0.0, 1.0], [0.0, -1.0 / tau]])
    M = np.zeros((4, 4))
    M[:2, :2] = -F
    M[1, 3] = 1.0
    M[2:, 2:] = F.T
    E = expm(M * dt)
    A = E[2:, 2:].T
    return A, A @ E[:2, 2:]


def _ref_guard(meas, est):
    """Independent causal step guard of robust_online, by loops: where the input is present
    at frames k-1 and k, the output step is at most the largest input step so far."""
    out = np.array(est, dtype=float)
    present = np.isfinite(meas).all(axis=-1)
    largest = -1.0
    for k in range(1, len(out)):
        if present[k] and present[k - 1]:
            largest = max(largest, float(np.linalg.norm(meas[k] - meas[k - 1])))
            d = out[k] - out[k - 1]
            n = float(np.linalg.norm(d))
            if np.isfinite(n) and n > largest:
                out[k] = out[k - 1] + d * (largest / n)
    return out


def _ref_filter(y, r, times, tau, q, *, ok=None, lookback=0, smooth=False):
    """Independent per-axis OU-velocity Kalman filter (and RTS smoother).

    y (T, 3) measurements (NaN: no update), r (T,) their variances, times (T,) s.
    Causal (smooth=False): starts at the first measurement with P = diag(r, q tau / 2)
    (velocity variance 1 m²/s² for tau = inf, the constant-velocity model);
    when a rejection starts (`ok` False after True) the state is re-predicted from
    `lookback` + 1 frames back.  smooth=True: Kalman filter from x0 = (first
    measurement, 0), P0 = diag(r, q tau / 2) at frame 0 (which is then updated with it),
    and the RTS smoother.
    """
    T = len(y)
    ok = np.isfinite(y).all(axis=-1) if ok is None else ok
    H = np.array([1.0, 0.0])
    I2 = np.eye(2)
    out = np.full((T, 3), np.nan)
    for ax in range(3):
        x = P = None
        xs, Ps, xp_, Pp_, As = [], [], [], [], []
        for k in range(T):
            A, Q = _ou_step(float(times[k] - times[k - 1]), tau) if k > 0 else (I2, 0 * I2)
            if x is None and not np.isfinite(y[k, ax]):
                xs.append(None), Ps.append(None), xp_.append(None), Pp_.append(None)
                As.append(A)
                continue
            if x is None:
                x = np.array([y[k, ax], 0.0])
                P = np.diag([r[k], q * tau / 2 if np.isfinite(tau) else 1.0])
                if not smooth:
                    xs.append(x), Ps.append(P), xp_.append(x), Pp_.append(P), As.append(A)
                    out[k, ax] = x[0]
                    continue
            s0 = k - lookback - 1
            if lookback and s0 >= 0 and ok[k - 1] and not ok[k] and ok[s0] and xs[s0] is not None:
                x, P = xs[s0], Ps[s0]
                for i in range(s0 + 1, k):
                    A_i, Q_i = _ou_step(float(times[i] - times[i - 1]), tau)
                    x, P = A_i @ x, A_i @ P @ A_i.T + q * Q_i
            x, P = A @ x, A @ P @ A.T + q * Q
            xp_.append(x), Pp_.append(P), As.append(A)
            if np.isfinite(y[k, ax]):
                S = H @ P @ H + r[k]
                K = P @ H / S
                x = x + K * (y[k, ax] - x[0])
                P = P - np.outer(K, H @ P)
            xs.append(x), Ps.append(P)
            out[k, ax] = x[0]
        if smooth:
            xsm, Psm = xs[-1], Ps[-1]
            for k in range(T - 2, -1, -1):
                if xs[k] is None:
                    break
                G = Ps[k] @ As[k + 1].T @ np.linalg.inv(Pp_[k + 1])
                xsm = xs[k] + G @ (xsm - xp_[k + 1])
                Psm = Ps[k] + G @ (Psm - Pp_[k + 1]) @ G.T
                out[k, ax] = xsm[0]
            out[T - 1, ax] = xs[-1][0]
    return out


def _irregular_recording(T=60, seed=0):
    """One root joint moving smoothly, irregular timestamps, NaN, NOT_TRACKED (reported
    at the origin) and INFERRED samples."""
    rng = np.random.default_rng(seed)
    ts = np.concatenate([[0.0], np.cumsum(rng.uniform(0.025, 0.045, T - 1))])
    pos = _point(T)
    pos[:, 0] += 0.15 * np.sin(2.0 * ts)[:, None] * np.array([1.0, -0.5, 0.3])
    pos += rng.normal(scale=0.004, size=pos.shape)
    states = np.full((T, 1), TRACKED, dtype=np.int8)
    states[[5, 12, 13, 30, 41], 0] = INFERRED
    states[[20, 21, 22], 0] = NOT_TRACKED
    pos[[20, 21, 22], 0] = 0.0  # what the sensor reports when it has no idea
    pos[35:38, 0] = np.nan
    return ts, pos, states


@pytest.mark.parametrize("tau", [0.2, 50.0, np.inf])
def test_online_filter_is_the_documented_ou_kalman_filter(tau):
    # docs/robust.md step 7: each axis an integrated OU velocity model, discretised
    # exactly per (irregular) step, q = 2 speed_sd² / tau (speed_sd² for tau = inf, the
    # constant-velocity model), measurement variance noise_sd² (x inferred_noise_factor
    # for INFERRED), NOT_TRACKED and NaN skipped.  tau = 50 s makes every step short
    # against tau (dt < 1e-3 tau).  lookback 0: the roll-back is tested above.
    ts, pos, states = _irregular_recording()
    seq = _seq(pos, states, timestamps=ts)
    sd, spd, factor = 0.008, 0.4, 3.0
    q = 2 * spd**2 / tau if np.isfinite(tau) else spd**2
    out = tk.smooth(
        seq,
        "robust_online",
        noise_sd=sd,
        speed_sd=spd,
        tau=tau,
        lookback=0,
        inferred_noise_factor=factor,
    )
    assert not out.metadata["diagnostics"]["rejected"].any()
    y = pos[:, 0].copy()
    y[states[:, 0] == NOT_TRACKED] = np.nan
    r = np.where(states[:, 0] == INFERRED, factor * sd**2, sd**2)
    ref = _ref_filter(y, r, ts, tau, q)
    np.testing.assert_allclose(out.positions[:, 0], ref, rtol=0, atol=1e-10)


def test_offline_smoother_is_the_documented_ou_kalman_rts_smoother():
    ts, pos, states = _irregular_recording(seed=1)
    states[0, 0] = TRACKED
    seq = _seq(pos, states, timestamps=ts)
    sd, spd, tau, factor = 0.008, 0.4, 0.2, 3.0
    out = tk.smooth(seq, "robust", noise_sd=sd, speed_sd=spd, tau=tau, inferred_noise_factor=factor,
                    noise="fixed", reweight=0)  # fmt: skip
    assert not out.metadata["diagnostics"]["rejected"].any()
    y = pos[:, 0].copy()
    y[states[:, 0] == NOT_TRACKED] = np.nan
    r = np.where(states[:, 0] == INFERRED, factor * sd**2, sd**2)
    ref = _ref_filter(y, r, ts, tau, 2 * spd**2 / tau, smooth=True)
    np.testing.assert_allclose(out.positions[:, 0], ref, rtol=0, atol=1e-10)


@pytest.mark.parametrize("tau", [0.1, 0.3])
def test_lost_joint_velocity_decays_with_tau(tau):
    # after the last measurement the OU velocity decays by exp(-dt / tau) per step, so
    # the successive increments of the (predicted) output shrink by exactly that factor
    # and a lost joint is extrapolated by a finite v * tau, then held.
    pos = _point(60)
    pos[:, 0, 0] = 0.02 * np.arange(60)  # 0.6 m/s
    pos[30:] = np.nan
    est, _ = _run(pos, "robust_online", tau=tau, lookback=0)  # lookback: tested above
    # (from frame 30: the step guard may hold frame 29 back by the filter's catch-up)
    steps = np.diff(est[30:, 0, 0])
    np.testing.assert_allclose(steps[1:] / steps[:-1], np.exp(-DT / tau), rtol=1e-9)
    assert 0.5 * 0.6 * tau < est[-1, 0, 0] - est[29, 0, 0] < 1.1 * 0.6 * tau


@pytest.mark.parametrize("method", [*ROBUST, "kf", "atkf"])
def test_estimates_start_at_each_joints_first_measurement(method):
    # no estimate before a joint's first valid measurement, one at every frame after it
    # (later gaps are bridged or predicted), whichever joints start later
    pos = _arm(40)
    pos[:7, 1] = np.nan
    pos[:12, 2] = np.nan
    pos[20:23, 0] = np.nan
    est = tk.smooth(_seq(pos), method).positions
    for j, first in ((0, 0), (1, 7), (2, 12)):
        assert np.isnan(est[:first, j]).all() and np.isfinite(est[first:, j]).all(), j


# ----------------------------------------------------------------------------- states
def _moving(T=50, J=3, seed=0):
    """J independent joints moving, noisy; joint 0 spikes 0.6 m at frame 20 (clipped by
    the ATKF limits) and joint J-1 is clipped at the Kinect's 5 m depth limit in 5-7 (a
    clipping sensor reports the limit itself)."""
    rng = np.random.default_rng(seed)
    t = np.arange(T) * DT
    base = np.array([0.2, 0.5, 2.5]) + rng.uniform(-0.3, 0.3, (J, 3))
    pos = base + 0.2 * np.sin(3 * t)[:, None, None] + rng.normal(scale=0.01, size=(T, J, 3))
    pos[20, 0] += [0.6, -0.6, 0.6]
    pos[5:8, J - 1, 2] = 5.0
    states = np.full((T, J), TRACKED, dtype=np.int8)
    states[rng.random((T, J)) < 0.3] = INFERRED
    states[0] = TRACKED
    return pos, states


def _points_seq(pos, states=None):
    names = [f"Spine{i}" for i in range(pos.shape[1])]  # torso, no bones
    return tk.SkeletonSequence(
        positions=pos, topology=tk.Topology.from_names(names), tracking_state=states, fps=FPS
    )


@pytest.mark.parametrize("method", ["kf", "kf+rts", "tkf", "tkfc", "atkf"])
def test_kalman_methods_scale_the_variance_of_inferred_joints(method):
    # smooth(): A = H = I, Q = q I, R = r I, x0 = first measurement, P0 = R; an INFERRED
    # sample gets R * inferred_noise_factor.  The same numbers from the public filters.
    pos, states = _moving()
    factor = 2.5
    name, offline = ("kf", True) if method == "kf+rts" else (method, False)
    out = tk.smooth(_points_seq(pos, states), name, offline=offline, inferred_noise_factor=factor)
    d = tk.smooth(_points_seq(pos), name).metadata["diagnostics"]["params"]
    q, r = d["q"], d["r"]
    R = r * np.eye(3)
    model = tk.LinearGaussian(A=np.eye(3), H=np.eye(3), Q=q * np.eye(3), R=R, x0=pos[0], P0=R)
    scale = np.repeat(np.where(states == INFERRED, factor, 1.0)[..., None], 3, axis=-1)
    if name == "kf":
        ref = tk.kalman_filter(model, pos, R_scale=scale)
        expected = tk.rts_smooth(model, ref).means if offline else ref.means
    elif name == "atkf":
        c = (0.34, 0.18, 0.34)  # horizontal / vertical (y up) per 1/30 s
        ref = tk.adaptive_tobit_filter(model, pos, c, R_scale=scale)
        expected = ref.means
    else:
        variant = "standard" if name == "tkf" else "corrected"
        lo, hi = (-3.0, -1.5, 0.5), (3.0, 3.0, 5.0)  # Kinect device limits
        ref = tk.tobit_filter(model, pos, lo, hi, variant=variant, R_scale=scale)
        expected = ref.means
    np.testing.assert_allclose(out.positions, expected, rtol=0, atol=1e-12)
    # diagnostics: the fraction of frames whose measurement the filter clipped, per joint
    clipped = ref.clipped.any(axis=-1).mean(axis=0)
    np.testing.assert_array_equal(out.metadata["diagnostics"]["clipped_fraction"], clipped)
    assert clipped.any() == (name != "kf")
    plain = tk.smooth(_points_seq(pos, states), name, offline=offline).positions
    assert np.abs(plain - out.positions).max() > 1e-4  # the factor matters here


LIVE = ("atkf", "atkf2016", "kf", "tkf", "tkfc")


@pytest.mark.parametrize("method", LIVE)
def test_live_equals_batch_with_inferred_joints_and_a_non_default_factor(method):
    pos, states = _moving(T=40, seed=2)
    states[10:14, 1] = NOT_TRACKED
    factor = 9.0
    seq = _points_seq(pos, states)
    batch = tk.smooth(seq, method, inferred_noise_factor=factor)
    live = tk.LiveSmoother(seq.topology, method, fps=FPS, inferred_noise_factor=factor)
    out, clipped = [], []
    for k in range(len(pos)):
        out.append(live.update(pos[k], states[k]))
        clipped.append(np.zeros(3, bool) if live.clipped is None else live.clipped)
    np.testing.assert_allclose(np.stack(out), batch.positions, rtol=0, atol=1e-12)
    assert live.n_frames == len(pos)
    # live.clipped: which joints' measurements were clipped in the last frame
    d = batch.metadata["diagnostics"]
    np.testing.assert_array_equal(np.mean(clipped, axis=0), d["clipped_fraction"])
    live.reset()
    assert live.n_frames == 0 and live.clipped is None
    # the factor is used at all: 9 and the default 4 differ
    default = tk.smooth(seq, method).positions
    assert np.abs(default - batch.positions).max() > 1e-4


def test_atkf_limits_widen_with_the_time_since_the_last_measurement():
    # smooth() "Gaps": at frame k the ATKF half-width is c * elapsed / (1/30 s), elapsed
    # = the time since the joint's last valid measurement.  Joint 0 is seen at frame 0
    # only and again from frame 10, 0.5 m away (c * 10 frames lets that through); joint
    # 1 misses 15-17 and 30-31.  The same numbers come live, frame by frame.
    pos, _ = _moving(T=40, J=2, seed=3)
    pos[1:10, 0] = np.nan
    pos[10:, 0] += [0.5, 0.0, 0.0]
    pos[15:18, 1] = np.nan
    pos[30:32, 1] = np.nan
    frames = np.zeros((40, 2))  # frames since the last valid measurement
    for j in range(2):
        last = None
        for k in range(40):
            frames[k, j] = 1 if last is None else k - last
            if np.isfinite(pos[k, j]).all():
                last = k
    assert frames[10, 0] == 10 and frames[18, 1] == 4 and frames[32, 1] == 3
    c = np.array([0.34, 0.18, 0.34])
    R = 0.01 * np.eye(3)
    model = tk.LinearGaussian(A=np.eye(3), H=np.eye(3), Q=0.0025 * np.eye(3), R=R, x0=pos[0], P0=R)
    ref = tk.adaptive_tobit_filter(model, pos, c_seq=c * frames[..., None]).means
    seq = _points_seq(pos)
    out = tk.smooth(seq, "atkf").positions
    np.testing.assert_allclose(out, ref, rtol=0, atol=1e-12)
    narrow = tk.adaptive_tobit_filter(model, pos, c).means  # limits not widened
    assert out[10, 0, 0] > narrow[10, 0, 0] + 0.05  # follows the reappeared joint faster
    live = tk.LiveSmoother(seq.topology, "atkf", fps=FPS)
    out_live = np.stack([live.update(p) for p in pos])
    np.testing.assert_allclose(out_live, out, rtol=0, atol=1e-12)


@pytest.mark.parametrize("method", [*ROBUST, "kf", "atkf", "tkfc"])
def test_not_tracked_is_missing_whatever_position_is_reported(method):
    # NOT_TRACKED samples reported at the origin (or anywhere) give exactly what NaN
    # gives: they are missing, neither measured nor rejected, and they get an estimate
    pos = _arm(60) + (0.05 * np.sin(np.arange(60) * DT * 4))[:, None, None]
    states = np.full(pos.shape[:2], TRACKED, dtype=np.int8)
    states[20:26, 1] = NOT_TRACKED
    zeros, nans = pos.copy(), pos.copy()
    zeros[20:26, 1] = 0.0
    nans[20:26, 1] = np.nan
    a = tk.smooth(_seq(zeros, states), method)
    b = tk.smooth(_seq(nans), method)
    np.testing.assert_array_equal(a.positions, b.positions)
    assert np.isfinite(a.positions).all()
    da = a.metadata["diagnostics"]
    assert da["filled_fraction"][1] == pytest.approx(6 / 60)
    if method in ROBUST:
        assert not da["rejected"].any()
    if method in LIVE:
        live = tk.LiveSmoother(_seq(zeros).topology, method, fps=FPS)
        out = np.stack([live.update(zeros[k], states[k]) for k in range(60)])
        np.testing.assert_allclose(out, a.positions, rtol=0, atol=1e-12)


# ----------------------------------------------------------------------------- online
def test_online_bone_gate_learns_the_length_from_15_accepted_frames():
    # online the reference length is the median of the bones accepted so far, used once
    # 15 of them are known (recomputed every 5 frames): frame 15.  The elbow is 10 cm
    # too far out (tolerance 7.5 cm) in frames 15-24: rejected from 15 on.  Started at
    # frame 10 instead, the first 5 frames pass (nothing learnt yet) and are learnt.
    for start, expected in ((15, _span(15, 24)), (10, _span(15, 24))):
        pos = _arm(60, joints=2)
        pos[start:25, 1, 0] += 0.10
        _, rej = _run(pos, "robust_online", v_max=10.0, min_run=0.0)
        assert _frames(rej[:, 1]) == expected, start


def test_online_chain_rule_holds_from_the_second_frame():
    # elbow and wrist jump 0.3 m together at frame 1 (v_max 3: 0.15 m per frame).  No
    # bone is known online yet; the speed gate rejects the elbow in 1-2 (0.25 m after 2
    # frames) and accepts it at 3 (0.35 m); the wrist, beside a rejected parent, jumped:
    # rejected in 1-2 as well, by the gate itself (min_run 0: no confirmation and no
    # second chain pass) and with the defaults.
    pos = _arm(30)
    pos[1:, 1:] += OFF
    for min_run in (0.0, 0.1):
        _, rej = _run(pos, "robust_online", v_max=3.0, min_run=min_run)
        assert _frames(rej[:, 1]) == [1, 2]
        assert _frames(rej[:, 2]) == [1, 2]


def test_online_is_causal():
    # robust_online decides frame t from frames <= t only: the output and the mask of
    # a prefix are those of the whole recording.  The elbow's bone grows to 0.4 m at
    # frame 40 for good, so the whole recording's median bone (0.4 m) differs from the
    # running one; and the arm has a failure (20-29) and a spike (35).
    pos = _arm(120)
    pos[20:30, 1:] += OFF
    pos[35, 2] += [0.3, 0.3, 0.0]
    pos[40:, 1:] += [0.1, 0.0, 0.0]
    est, rej = _run(pos, "robust_online")
    assert rej[20:30, 1].all() and rej[35, 2]
    for cut in (30, 45, 80):
        e, r = _run(pos[:cut], "robust_online")
        np.testing.assert_array_equal(r, rej[:cut])
        np.testing.assert_allclose(e, est[:cut], rtol=0, atol=1e-12)


def test_offline_gate_rejects_what_only_the_backward_pass_flags():
    # v_max 1 m/s at 30 fps: a step of at most 1/30 + 0.05 = 0.083 m passes. The joint
    # drifts away in steps of 0.07 m (frames 30-32, accepted going forwards), stays 0.28 m
    # off until frame 59 and jumps back at frame 60. Going backwards, frames 59..54 are
    # 0.28 m from frame 60 with gates k / 30 + 0.05 < 0.28 (k = 1..6 frames) and are
    # rejected, frame 53 (k = 7: 0.283) is accepted; going forwards, the return 60..65
    # is rejected the same way. Offline a sample is rejected when either pass rejects it.
    pos = _point(90)
    pos[30:33, 0, 0] = [0.07, 0.14, 0.21]
    pos[33:60, 0, 0] = 0.28
    _, rej = _run(pos, "robust", v_max=1.0)
    assert _frames(rej[:, 0]) == _span(54, 65)


def test_offline_carry_takes_the_next_offset_when_there_is_no_earlier_one():
    # the shoulder walks 0.6 m along x; the elbow (0.3 m beside it) is wrong from the
    # first frame until frame 19, so there is no earlier good offset: the stretch is
    # carried with the next one (frame 20).  The bridged elbow follows the shoulder.
    T = 60
    pos = _arm(T, joints=2) + np.linspace(0.0, 0.6, T)[:, None, None] * [1.0, 0.0, 0.0]
    meas = pos.copy()
    meas[:20, 1] += OFF
    est, rej = _run(meas, "robust")
    assert _frames(rej[:, 1]) == _span(0, 19)
    err = np.linalg.norm(est[:20, 1] - pos[:20, 1], axis=-1).max()
    held, _ = _run(meas, "robust", carry=False)
    err_held = np.linalg.norm(held[:20, 1] - pos[:20, 1], axis=-1).max()
    assert err < 0.02 and err < 0.3 * err_held, (err, err_held)


@pytest.mark.parametrize("method", ROBUST)
def test_robust_reports_the_per_joint_parameters_it_used(method):
    # regions by joint name: shoulder and elbow are arms, the wrist is a hand
    out = tk.smooth(_seq(_arm(20)), method, v_max={"hands": 7, "arms": 4, "torso": 2, "legs": 9})
    p = out.metadata["diagnostics"]["params"]
    assert p["v_max"] == [4.0, 4.0, 7.0]
    assert p["speed_sd"] == [0.6, 0.6, 1.0]
    assert p["noise_sd"] == [0.01, 0.01, 0.015]
    assert p["offline"] == (method == "robust")
    # the documented defaults (docs/robust.md, table of parameters)
    p = tk.smooth(_seq(_arm(20)), method).metadata["diagnostics"]["params"]
    assert p["v_max"] == [5.0, 5.0, 8.0]
    documented = {
        "margin": 0.05,
        "bone_tol_abs": 0.03,
        "bone_tol_rel": 0.15,
        "tau": 0.15,
        "max_reject": 2.0,
        "min_run": 0.1,
        "lookback": 2,
        "inferred_noise_factor": 4.0,
        "bones": True,
        "two_pass": True,
        "carry": True,
    }
    assert {k: p[k] for k in documented} == documented
    p = tk.smooth(_seq(_arm(20)), "kf").metadata["diagnostics"]["params"]
    assert p["inferred_noise_factor"] == 4.0 and p["offline"] is False
    with pytest.raises(ValueError, match="v_max"):
        tk.smooth(_seq(_arm(20)), method, v_max=0.0)
    with pytest.raises(ValueError, match="tau must be a number"):
        tk.smooth(_seq(_arm(20)), method, tau="slow")


def test_smooth_accepts_per_joint_robust_parameters():
    seq = _seq(_arm(20))
    by_joint = tk.smooth(seq, "robust", v_max=np.array([4.0, 4.0, 7.0]))
    by_region = tk.smooth(seq, "robust", v_max={"hands": 7, "arms": 4, "torso": 3, "legs": 9})
    np.testing.assert_array_equal(by_joint.positions, by_region.positions)


def test_lists_of_bodies_keep_up_axis_and_inferred_factor():
    pos, states = _moving(T=30, J=2, seed=4)
    a, b = _points_seq(pos, states), _points_seq(pos[:, ::-1].copy(), states[:, ::-1].copy())
    kw = {"up_axis": 2, "inferred_noise_factor": 6.0}
    for method in ("atkf", "kf"):
        both = tk.smooth([a, b], method, **kw)
        for one, seq in zip(both, (a, b), strict=True):
            np.testing.assert_array_equal(one.positions, tk.smooth(seq, method, **kw).positions)
        assert both[0].metadata["diagnostics"]["params"]["up_axis"] == 2


def test_explicit_c_and_per_axis_noise_reach_the_filters():
    pos, _ = _moving(T=30, J=2, seed=5)
    q, r, c = (0.001, 0.002, 0.003), (0.02, 0.01, 0.03), (0.3, 0.1, 0.2)
    model = tk.LinearGaussian(
        A=np.eye(3), H=np.eye(3), Q=np.diag(q), R=np.diag(r), x0=pos[0], P0=np.diag(r)
    )
    out = tk.smooth(_points_seq(pos), "atkf", q=q, r=r, c=c).positions
    ref = tk.adaptive_tobit_filter(model, pos, np.array(c)).means
    np.testing.assert_allclose(out, ref, rtol=0, atol=1e-12)
    out = tk.smooth(_points_seq(pos), "kf", q=q, r=r).positions
    np.testing.assert_allclose(out, tk.kalman_filter(model, pos).means, rtol=0, atol=1e-12)


def test_live_smoother_defaults():
    live = tk.LiveSmoother()
    assert live.topology.name == "kinect_v2" and live.method == "robust_online"


# ----------------------------------------------------------------------------- EPS_CENSORED
EPS = 1e-9  # documented in the Tobit filters' docstring


def _mills(a):
    """Q(a) / phi(a), stable for large a."""
    return np.sqrt(np.pi / 2) * special.erfcx(a / np.sqrt(2))


def _one_sided(a):
    """P_un, P_censored and the variance of max(Z, a), Z ~ N(0, 1) (stable)."""
    phi = np.exp(-0.5 * a * a) / np.sqrt(2 * np.pi)
    R = _mills(a)
    w1 = phi * (1 - a * R)  # E[max(Z - a, 0)]
    w2 = phi * ((1 + a * a) * R - a)  # E[max(Z - a, 0)^2]
    return R * phi, special.ndtr(a), w2 - w1 * w1


def _measured_gain(filt, model, ys, y1, y2, **kw):
    """Gain of the (last) update, from two measurements inside the limits."""
    means = filt(model, np.stack([ys, ys], axis=1), **kw).means
    d = means[-1, 1, 0] - means[-1, 0, 0]
    return d / (y2 - y1)


def _scalar_model(P, r, q=0.0):
    return tk.LinearGaussian(
        A=np.eye(1), H=np.eye(1), Q=q * np.eye(1), R=r * np.eye(1), x0=np.zeros(1), P0=P * np.eye(1)
    )


@pytest.mark.parametrize("side", ["lower", "upper"])
@pytest.mark.parametrize("diagonal", [True, False])
def test_censored_gain_profile_of_the_corrected_tobit_filter(side, diagonal):
    # TKF^c, one limit alpha predicted sd beyond the mean: Pxy = P P_un, Pyy = S (Var f +
    # EPS P_c), so the gain relative to the KF's P / S is P_un / (Var f + EPS P_c).  The
    # docstring's measured profile: 1.5, 6.6, 14.1 (peak), 0.94, 1e-3, 8e-15.
    P, r = 0.04, 0.01
    S = P + r
    s = np.sqrt(S)
    model = _scalar_model(P, r)
    doc = {0.0: 1.5, 3.0: 6.6, 5.0: 14.1, 6.0: 0.94, 7.0: 1.3e-3, 10.0: 7.6e-15}
    for alpha, documented in doc.items():
        pu, pc, var = _one_sided(alpha)
        if side == "lower":
            limits = {"lower": alpha * s, "upper": np.inf}
            y1, y2 = alpha * s + 0.1 * s, alpha * s + 0.4 * s
        else:
            limits = {"lower": -np.inf, "upper": -alpha * s}
            y1, y2 = -alpha * s - 0.4 * s, -alpha * s - 0.1 * s
        ys = np.array([[[y1], [y2]]])[:, :, :]
        means = tk.tobit_filter(model, ys, diagonal=diagonal, **limits).means
        gain = (means[0, 1, 0] - means[0, 0, 0]) / (y2 - y1) / (P / S)
        expected = pu / (var + EPS * pc)
        np.testing.assert_allclose(gain, expected, rtol=1e-6, err_msg=f"alpha={alpha}")
        np.testing.assert_allclose(gain, documented, rtol=0.05)


@pytest.mark.parametrize("side", ["lower", "upper"])
def test_censored_gain_of_the_standard_tobit_filter(side):
    # Allik's TKF: probabilities from R, Pyy = P_un² P + R (v_T + EPS P_c), Pxy = P P_un
    P, r = 0.04, 0.01
    model = _scalar_model(P, r)
    sr = np.sqrt(r)
    for alpha in (0.0, 3.0, 5.0, 7.0, 9.0):
        pu, pc, _ = _one_sided(alpha)
        lam = 1.0 / _mills(alpha)
        v_t = 1.0 + alpha * lam - lam * lam
        if side == "lower":
            lo, hi = alpha * sr, np.inf
            y1, y2 = alpha * sr + 0.1 * sr, alpha * sr + 0.3 * sr
        else:
            lo, hi = -np.inf, -alpha * sr
            y1, y2 = -alpha * sr - 0.3 * sr, -alpha * sr - 0.1 * sr
        ys = np.array([[[y1], [y2]]])
        means = tk.tobit_filter(model, ys, lo, hi, variant="standard").means
        gain = (means[0, 1, 0] - means[0, 0, 0]) / (y2 - y1)
        expected = P * pu / (pu * pu * P + r * (v_t + EPS * pc))
        np.testing.assert_allclose(gain, expected, rtol=1e-6, err_msg=f"alpha={alpha}")


def test_standard_tobit_gain_in_a_narrow_interval():
    # limits [a, a + w] standard deviations (of R) above the prediction: v_T -> w² / 12
    # (uniform), so for w <~ 1e-4 the EPS (P_a + P_b) floor is what bounds the gain
    P, r = 0.04, 0.01
    model = _scalar_model(P, r)
    sr = np.sqrt(r)
    a = 0.3
    for w in (1e-3, 1e-4, 1e-5):
        b = a + w
        pu = special.ndtr(b) - special.ndtr(a)
        floor = w * w / 12 + EPS * (special.ndtr(a) + special.ndtr(-b))
        y1, y2 = (a + 0.2 * w) * sr, (a + 0.7 * w) * sr
        ys = np.array([[[y1], [y2]]])
        means = tk.tobit_filter(model, ys, a * sr, b * sr, variant="standard").means
        gain = (means[0, 1, 0] - means[0, 0, 0]) / (y2 - y1)
        expected = P * pu / (pu * pu * P + r * floor)
        np.testing.assert_allclose(gain, expected, rtol=1e-6, err_msg=f"w={w}")


def test_censored_gain_of_the_adaptive_filter_in_a_narrow_interval():
    # ATKF step 1: limits x_0 ± c around the prediction m; with beta = c / sqrt(S) the
    # gain is P⁻ P_un / (S (Var f + 2 EPS P_a)).  For a very narrow interval the EPS
    # term dominates and the gain goes to 0 (docstring, last paragraph).
    P0, r, q = 0.04, 0.01, 0.0025
    model = _scalar_model(P0, r, q)
    Pm = (P0 + q) * r / (P0 + q + r) + q  # predicted, KF step 0 at y = 0 (x stays 0), predicted
    S = Pm + r
    gains = {}
    for beta in (1e-10, 1e-5, 1e-4, 1e-3, 0.5, 2.0):
        c = beta * np.sqrt(S)
        pa = special.ndtr(-beta)
        pu = special.erf(beta / np.sqrt(2))
        phi = np.exp(-0.5 * beta * beta) / np.sqrt(2 * np.pi)
        var = (pu - 2 * beta * phi) + 2 * beta * beta * pa
        y1, y2 = -0.5 * c, 0.3 * c
        ys = np.array([[[0.0], [0.0]], [[y1], [y2]]])
        res = tk.adaptive_tobit_filter(model, ys, c)
        means = res.means
        gain = (means[1, 1, 0] - means[1, 0, 0]) / (y2 - y1)
        # symmetric limits: P_a = P_b = Q(beta), and the three probabilities add up to 1
        np.testing.assert_allclose(res.p_upper[1], pa, rtol=1e-12)
        np.testing.assert_allclose(res.p_lower[1] + res.p_uncensored[1] + res.p_upper[1], 1.0)
        expected = Pm * pu / (S * (var + 2 * EPS * pa))
        np.testing.assert_allclose(gain, expected, rtol=1e-6, err_msg=f"beta={beta}")
        gains[beta] = gain
    # without EPS the gain would grow like 0.8 / beta; with it, it peaks near
    # beta = sqrt(EPS) and falls below the KF gain for a vanishing interval
    assert gains[1e-10] < 0.1 * Pm / S < gains[1e-4]


def _tobit_module():
    for name in ("tobitkf.core.tobit", "tobitkf.tobit"):
        try:
            mod = importlib.import_module(name)
        except ImportError:
            continue
        if hasattr(mod, "EPS_CENSORED"):
            return mod
    pytest.skip("EPS_CENSORED not found")


def test_gain_profile_test_fails_with_another_eps(monkeypatch):
    # the tests above would notice EPS_CENSORED = 1e-6 (the docstring: a lower peak)
    mod = _tobit_module()
    P, r = 0.04, 0.01
    s = np.sqrt(P + r)
    model = _scalar_model(P, r)
    ys = np.array([[[5.1 * s], [5.4 * s]]])

    def gain():
        means = tk.tobit_filter(model, ys, 5.0 * s, np.inf).means
        return (means[0, 1, 0] - means[0, 0, 0]) / (0.3 * s) / (P / (P + r))

    assert gain() == pytest.approx(14.1, rel=0.01)
    monkeypatch.setattr(mod, "EPS_CENSORED", 1e-6)
    assert gain() < 1.0


@pytest.mark.parametrize("method", ROBUST)
def test_a_missing_parent_is_no_evidence_against_its_child(method):
    # issue 14 point 6: with half of the samples dropped, joints whose parent was missing
    # when they were first seen were treated as if the parent had been rejected, never
    # accepted, and returned NaN (57 of 1,474 samples). Every sample from a joint's first
    # measurement on must have an estimate.
    pos = _arm(60, joints=3)
    rng = np.random.default_rng(3)
    pos[rng.random(pos.shape[:2]) < 0.5] = np.nan
    est, rej = _run(pos, method)
    started = np.maximum.accumulate(np.isfinite(pos).all(axis=-1), axis=0)
    assert np.isfinite(est[started]).all()
    assert not rej.any()  # a smooth arm: nothing is impossible


def test_a_long_chain_is_smoothed():
    # issue 14 point 6: a 1,000-joint chain (60 frames) took over 60 s; now every rule is
    # linear in the joints (the time is measured in benchmarks, not here)
    J = 1000
    topo = tk.Topology.from_names([f"j{i}" for i in range(J)], parents=[-1, *range(J - 1)])
    rng = np.random.default_rng(0)
    # 5 mm bones: 5 m in all (a body whose joints lay tens of metres from their centre
    # would not be in metres, smoothing/body_scale.py)
    pos = np.cumsum(rng.normal(0, 0.005, (60, J, 3)), axis=0) + np.arange(J)[None, :, None] * 0.005
    for method in ROBUST:
        out = tk.smooth(tk.SkeletonSequence(positions=pos, topology=topo, fps=30.0), method)
        assert np.isfinite(out.positions).all()


@pytest.mark.parametrize("method", ["robust", "robust_online"])
def test_the_same_times_give_the_same_output_whether_from_fps_or_stamps(method):
    """A Kinect recording timed by fps=30 and by timestamps k/30: its frame times agree
    to the last bits, and min_run (0.1 s, three steps at 30 fps) must not fall on either
    side of a run by rounding (it did, by up to 40 cm on KERAAL)."""
    from conftest import data_file

    (seq,) = tk.load(data_file("keraal/G3-Kinect-RTK-P1T1-Unknown-C-0.txt"))
    assert seq.timestamps is None and seq.fps == 30.0
    stamped = seq.replace(timestamps=np.arange(seq.n_frames) / 30.0, fps=None)
    np.testing.assert_allclose(stamped.times(), seq.times(), rtol=0, atol=1e-12)
    a, b = tk.smooth(seq, method), tk.smooth(stamped, method)
    np.testing.assert_array_equal(a.sample_state, b.sample_state)
    # (the noise fit reads steps that differ in their last bits: a tenth of a mm at most)
    np.testing.assert_allclose(a.positions, b.positions, rtol=0, atol=1e-4)

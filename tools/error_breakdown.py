"""Where a robust smoother's remaining error sits, against ground truth (docs/robust.md).

For each recording (Kinect track + simultaneous mocap, paired as ``tobitkf evaluate``
does) the samples are split by what the raw measurement was (a *glitch*: more than
``--threshold`` from the truth, else *good*) and by what the method did with it
(*accepted* or *rejected* by its gates); the table gives each class's share of the
method's squared error and its RMSE before and after. A last column counts samples that
look like a left/right swap (the raw joint is closer to the truth of its mirror joint
than to its own by more than the threshold).

``--truth-check`` adds what the truth itself gets wrong and what the accepted glitches
look like:

* *truth-inconsistent* samples: a joint at a frame where one of its bones in the truth
  (to its parent or to a child, on the track's topology) is off the bone's median length
  in that recording by more than the bone gate's tolerance (``bone_tol_abs +
  bone_tol_rel * L``, the robust defaults); how many, on which joints, their share of the
  method's squared error, and the pooled RMSE of raw / the method / ``robust_online``
  without them;
* per recording, the geometry of the raw track at the accepted glitches (glitch samples
  the method did not reject): the smallest interior angle at the middle joint of an arm
  (elbow) and the largest bend at its third (wrist; the angle between forearm and hand),
  over the frames where a joint of that arm from the elbow down is an accepted glitch;
  the largest rotation rate of a long limb segment (upper arm, forearm, thigh, shank) at
  a frame where one of its ends is an accepted glitch; and how many accepted glitch
  samples lie within ``--near`` of an accepted joint of another limb or of the trunk.
  A limb is the subtree under a mirrored joint whose parent is not mirrored (shoulder,
  hip); every other joint is trunk.

``--compare OTHER`` (for instance the causal ``robust_online`` against the offline
default) splits OTHER's extra squared error over the method's by what the two did with
the sample (both accepted it, both rejected it, only one of them rejected it), and
gives OTHER's pooled RMSE had it matched the method in some of these classes: what the
other method would have to recover to come level.

    python tools/error_breakdown.py TRACK... --truth-replace OLD NEW [--method robust]
                                    [--truth-check] [--compare robust_online]
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

import tobitkf as tk
from tobitkf.evaluation.angles import joint_angle
from tobitkf.evaluation.evaluate import evaluate_paths
from tobitkf.evaluation.metrics import glitch_episodes
from tobitkf.smoothing.robust import ROBUST_DEFAULTS

ONLINE = "robust_online"

CLASSES = (
    ("glitch, accepted", False, True),
    ("glitch, rejected", True, True),
    ("good, accepted", False, False),
    ("good, rejected", True, False),
)


def truth_inconsistent(
    truth: np.ndarray,
    parents: tuple[int, ...] | list[int],
    tol_abs: float = ROBUST_DEFAULTS["bone_tol_abs"],
    tol_rel: float = ROBUST_DEFAULTS["bone_tol_rel"],
) -> np.ndarray:
    """``(T, J)`` bool: the joint has a bone (to its parent or a child) whose length in
    ``truth`` ``(T, J, D)`` is off the bone's median length by more than ``tol_abs +
    tol_rel * median`` (the bone gate's rule applied to the truth). Missing is not off."""
    T, J = truth.shape[:2]
    off = np.zeros((T, J), dtype=bool)
    for j, p in enumerate(parents):
        if p < 0:
            continue
        length = np.linalg.norm(truth[:, j] - truth[:, p], axis=-1)
        if not np.isfinite(length).any():
            continue
        L = float(np.nanmedian(length))
        with np.errstate(invalid="ignore"):
            bad = np.abs(length - L) > tol_abs + tol_rel * L  # NaN compares False
        off[:, j] |= bad
        off[:, p] |= bad
    return off


def limbs(topology) -> np.ndarray:
    """``(J,)`` limb id per joint: the subtree under a mirrored joint whose parent is not
    mirrored (shoulder, hip) is a limb, numbered by that joint; the rest is trunk (-1)."""
    parents = topology.parents
    mirrored = {j for pair in topology.symmetry for j in pair}
    out = np.full(len(parents), -1)
    for j in range(len(parents)):
        k = j
        while k >= 0:
            if k in mirrored and parents[k] not in mirrored:
                out[j] = k
                break
            k = parents[k]
    return out


def _first_child(parents, j: int) -> int:
    kids = [c for c, p in enumerate(parents) if p == j]
    return min(kids) if kids else -1


def glitch_geometry(raw: np.ndarray, accepted: np.ndarray, rejected: np.ndarray, topology,
                    dt: float, near: float) -> dict:  # fmt: skip
    """Geometry of the raw track ``(T, J, D)`` at the accepted glitches ``(T, J)`` (bool;
    ``rejected`` ``(T, J)``: what the method rejected): see the module docstring (angles
    in degrees, rates in rad/s; NaN when none applies)."""
    par = topology.parents
    limb = limbs(topology)
    arms = set(topology.joint_groups()["arms"])
    elbow, wrist, segrate = [], [], []
    for root in sorted(set(limb[limb >= 0].tolist())):
        c1 = _first_child(par, root)
        c2 = _first_child(par, c1) if c1 >= 0 else -1
        c3 = _first_child(par, c2) if c2 >= 0 else -1
        if c2 < 0:
            continue
        for a, b in ((root, c1), (c1, c2)):  # long segments: upper arm / thigh, forearm / shank
            seg = raw[:, b] - raw[:, a]
            rate = np.radians(joint_angle(seg[1:], 0.0, seg[:-1])) / dt  # between frames
            kept = ~(rejected[1:, a] | rejected[1:, b] | rejected[:-1, a] | rejected[:-1, b])
            hit = (accepted[1:, a] | accepted[1:, b]) & kept & np.isfinite(rate)
            segrate.append(rate[hit])
        if root not in arms or c3 < 0:
            continue
        hit = accepted[:, [c1, c2, c3]].any(axis=1) & ~rejected[:, [root, c1, c2, c3]].any(axis=1)
        interior = joint_angle(raw[:, root], raw[:, c1], raw[:, c2])
        bend = 180.0 - joint_angle(raw[:, c1], raw[:, c2], raw[:, c3])  # 0: hand straight
        elbow.append(interior[hit & np.isfinite(interior)])
        wrist.append(bend[hit & np.isfinite(bend)])
    close = 0
    for t, j in zip(*np.nonzero(accepted)):
        other = np.flatnonzero((limb != limb[j]) & ~rejected[t])
        d = np.linalg.norm(raw[t, other] - raw[t, j], axis=-1)
        close += int(np.any(d < near))
    return {
        "elbow_min": _ext(np.concatenate(elbow) if elbow else [], np.min),
        "wrist_max": _ext(np.concatenate(wrist) if wrist else [], np.max),
        "rate_max": _ext(np.concatenate(segrate) if segrate else [], np.max),
        "near": close,
        "n": int(accepted.sum()),
    }


def _ext(values, fn) -> float:
    v = np.asarray(values, dtype=float)
    return float(fn(v)) if v.size else float("nan")


#: classes of samples by what the method and the one compared with it did (``--compare``)
COMPARE_CLASSES = ("both accepted", "both rejected", "only the other rejected",
                   "only the method rejected")  # fmt: skip


def compare_split(e_method: np.ndarray, e_other: np.ndarray, rej_method: np.ndarray,
                  rej_other: np.ndarray) -> dict[str, tuple[int, float, float]]:  # fmt: skip
    """Per class of :data:`COMPARE_CLASSES`: (samples, method's squared error, other's
    squared error), over the samples where both errors are known. ``rej_*``: what each
    rejected, same shape as the errors."""
    ok = np.isfinite(e_method) & np.isfinite(e_other)
    rm, ro = np.asarray(rej_method, bool), np.asarray(rej_other, bool)
    masks = (~rm & ~ro, rm & ro, ~rm & ro, rm & ~ro)
    out = {}
    for name, m in zip(COMPARE_CLASSES, masks, strict=True):
        m = m & ok
        out[name] = (int(m.sum()), float((e_method[m] ** 2).sum()), float((e_other[m] ** 2).sum()))
    return out


def compare_bounds(split: dict[str, tuple[int, float, float]]) -> list[tuple[str, float]]:
    """The other method's pooled squared error as measured, then had it matched the
    method's error in more and more classes (both accepted; and both rejected; and
    every class, which is the method's own)."""
    other = {k: v[2] for k, v in split.items()}
    method = {k: v[1] for k, v in split.items()}
    rows = [("as measured", sum(other.values()))]
    same: set[str] = set()
    for i, cls in enumerate(COMPARE_CLASSES):
        label = f"matched where {cls}" if i == 0 else f"... and where {cls}"
        same.add(cls)
        rows.append((label, sum(method[k] if k in same else other[k] for k in split)))
    return rows


def breakdown(track: str, truth: str, method: str, threshold: float,
              truth_check: bool = False, near: float = 0.05,
              compare: str | None = None) -> dict:  # fmt: skip
    outputs: dict = {}
    methods = [method, ONLINE] if truth_check and method != ONLINE else [method]
    if compare and compare not in methods:
        methods.append(compare)
    gt, _ = evaluate_paths(track, truth, methods, outputs=outputs)
    seq = tk.load(track)[0]
    est = outputs[method]
    t = gt.positions
    e_raw = np.linalg.norm(seq.positions - t, axis=-1)
    e_est = np.linalg.norm(est.positions - t, axis=-1)
    ok = np.isfinite(e_raw) & np.isfinite(e_est)
    rejected = np.asarray(est.metadata["diagnostics"].get("rejected", np.zeros_like(ok)))
    glitch = e_raw > threshold
    rows = {}
    for name, rej, gl in CLASSES:
        m = ok & (rejected == rej) & (glitch == gl)
        rows[name] = (int(m.sum()), float((e_raw[m] ** 2).sum()), float((e_est[m] ** 2).sum()))
    swaps = 0
    for a, b in seq.topology.symmetry:
        for j, k in ((a, b), (b, a)):
            mirror = np.linalg.norm(seq.positions[:, j] - t[:, k], axis=-1)
            swaps += int(np.sum(ok[:, j] & (mirror + threshold < e_raw[:, j])))
    res = {"rows": rows, "swaps": swaps, "n": int(ok.sum())}
    if compare:
        other = outputs[compare]
        e_other = np.linalg.norm(other.positions - t, axis=-1)
        rej_other = np.asarray(other.metadata["diagnostics"].get("rejected", np.zeros_like(ok)))
        res["compare"] = compare_split(np.where(ok, e_est, np.nan), e_other, rejected, rej_other)
    if truth_check:
        e_on = np.linalg.norm(outputs[ONLINE].positions - t, axis=-1)
        ok &= np.isfinite(e_on)
        bad = truth_inconsistent(t, seq.topology.parents) & ok
        keep = ok & ~bad
        res["truth"] = {
            "bad": bad,
            "joints": seq.topology.joints,
            "sse_bad": float((e_est[bad] ** 2).sum()),
            "sse_all": float((e_est[ok] ** 2).sum()),
            "all": (int(ok.sum()), *(float((e[ok] ** 2).sum()) for e in (e_raw, e_est, e_on))),
            "kept": (int(keep.sum()), *(float((e[keep] ** 2).sum()) for e in (e_raw, e_est, e_on))),
        }
        accepted = ok & glitch & ~rejected.astype(bool)
        res["geometry"] = glitch_geometry(
            seq.positions, accepted, rejected.astype(bool), seq.topology, 1.0 / seq.fps, near
        )
    return res


def parse_with_truth_replace(
    ap: argparse.ArgumentParser, argv: list[str] | None
) -> tuple[argparse.Namespace, tuple[str, str]]:
    """``ap``'s arguments and the required ``--truth-replace OLD NEW`` (truth = track path
    with OLD replaced by NEW), which argparse cannot take: OLD may look like an option
    ("-Kinect-")."""
    ap.epilog = "--truth-replace OLD NEW (required): truth = track path with OLD replaced by NEW"
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--truth-replace" not in argv or len(argv) < argv.index("--truth-replace") + 3:
        ap.error("--truth-replace OLD NEW is required")
    i = argv.index("--truth-replace")
    return ap.parse_args(argv[:i] + argv[i + 3 :]), (argv[i + 1], argv[i + 2])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("tracks", nargs="+")
    ap.add_argument("--method", default=tk.DEFAULT_METHOD)
    ap.add_argument("--threshold", type=float, default=0.10, help="glitch threshold, m")
    ap.add_argument("--truth-check", action="store_true",
                    help="also the truth's own bone-length failures and the accepted "
                         "glitches' geometry (module docstring)")  # fmt: skip
    ap.add_argument(
        "--near",
        type=float,
        default=0.05,
        help="--truth-check: distance to another limb's joint counted, m",
    )
    ap.add_argument("--compare", metavar="OTHER",
                    help="also split OTHER's extra error over the method's by what each "
                         "rejected (module docstring)")  # fmt: skip
    args, (old, new) = parse_with_truth_replace(ap, argv)
    print(f"| recording | class | samples | raw RMSE cm | {args.method} RMSE cm "
          f"| share of {args.method}'s squared error | swap-like samples |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    total = {name: [0, 0.0, 0.0] for name, _, _ in CLASSES}
    all_sse = 0.0
    results = {}
    for track in args.tracks:
        res = breakdown(track, track.replace(old, new), args.method, args.threshold,
                        args.truth_check, args.near, args.compare)  # fmt: skip
        results[track.rsplit("/", 1)[-1]] = res
        sse = sum(r[2] for r in res["rows"].values())
        all_sse += sse
        label = track.rsplit("/", 1)[-1]
        for i, (name, (n, raw, est)) in enumerate(res["rows"].items()):
            for k, v in enumerate((n, raw, est)):
                total[name][k] += v
            swaps = str(res["swaps"]) if i == 0 else ""
            print(f"| {label if i == 0 else ''} | {name} | {n} | {_rms(raw, n)} | "
                  f"{_rms(est, n)} | {est / sse:.0%} | {swaps} |")  # fmt: skip
    for name, (n, raw, est) in total.items():
        print(f"| all | {name} | {n} | {_rms(raw, n)} | {_rms(est, n)} | {est / all_sse:.0%} | |")
    print()
    print(f"Glitch: raw sample more than {100 * args.threshold:.0f} cm from the truth; "
          "accepted / rejected: by the method's gates.")  # fmt: skip
    print()
    _print_bounds(total, args.method)
    if args.truth_check:
        _print_truth_check(results, args.method, args.threshold, args.near)
    if args.compare:
        _print_compare(results, args.method, args.compare)
    return 0


def _print_compare(results: dict, method: str, other: str) -> None:
    split = {k: [0, 0.0, 0.0] for k in COMPARE_CLASSES}
    for res in results.values():
        for k, v in res["compare"].items():
            for i in range(3):
                split[k][i] += v[i]
    n = sum(v[0] for v in split.values())
    excess = sum(v[2] - v[1] for v in split.values())
    print()
    print(f"{other} against {method}, pooled over the recordings: the samples by what "
          f"the two did with them, and each class's share of {other}'s extra squared "
          "error:")  # fmt: skip
    print()
    print(f"| samples | count | {method} RMSE cm | {other} RMSE cm | share of the extra error |")
    print("|---|---|---|---|---|")
    for k, (c, sm, so) in split.items():
        share = f"{(so - sm) / excess:.0%}" if excess > 0 else "–"
        print(f"| {k} | {c} | {_rms(sm, c)} | {_rms(so, c)} | {share} |")
    print()
    print(f"Pooled RMSE of {other}, cm, had it matched {method} in these samples:")
    print()
    print(f"| {other} | RMSE |")
    print("|---|---|")
    for label, sse in compare_bounds({k: tuple(v) for k, v in split.items()}):
        print(f"| {label} | {_rms(sse, n, 2)} |")


def bounds(total: dict) -> list[tuple[str, float]]:
    """Pooled squared error of the method if some classes were exactly right: as
    measured; every rejected sample exactly right (a perfect bridge behind the same
    gates); every glitch and every rejected sample exactly right (perfect gates and
    bridge: only the smoothing of the good samples left). ``total``: class -> (n, raw
    sse, method sse)."""
    est = {name: v[2] for name, v in total.items()}
    return [
        ("as measured", sum(est.values())),
        ("every rejected sample exactly right", est["glitch, accepted"] + est["good, accepted"]),
        ("every glitch and every rejected sample exactly right", est["good, accepted"]),
    ]


def _print_bounds(total: dict, method: str) -> None:
    n = sum(v[0] for v in total.values())
    raw = sum(v[1] for v in total.values())
    print(f"Pooled RMSE of {method}, cm, if some samples were exactly right (what better "
          "bridging, or better gates and bridging, could reach at most):")  # fmt: skip
    print()
    print(f"| {method} | RMSE | vs raw |")
    print("|---|---|---|")
    print(f"| raw | {_rms(raw, n, 2)} | |")
    for name, sse in bounds(total):
        print(f"| {name} | {_rms(sse, n, 2)} | {np.sqrt(sse / raw) - 1:+.0%} |")


def _print_truth_check(results: dict, method: str, threshold: float, near: float) -> None:
    tol = f"{100 * ROBUST_DEFAULTS['bone_tol_abs']:.0f} cm + {ROBUST_DEFAULTS['bone_tol_rel']:.0%}"
    print()
    print(f"Truth-inconsistent samples (a bone of the joint in the truth is off its median "
          f"length by more than {tol} of it):")  # fmt: skip
    print()
    print(f"| recording | truth-inconsistent samples | joints (most first) | "
          f"share of {method}'s squared error |")  # fmt: skip
    print("|---|---|---|---|")
    n_bad = sse_bad = sse_all = 0.0
    pooled = {"all": np.zeros(4), "kept": np.zeros(4)}
    for label, res in results.items():
        tc = res["truth"]
        bad = tc["bad"]
        per = sorted(((int(c), -j) for j, c in enumerate(bad.sum(axis=0)) if c), reverse=True)
        joints = ", ".join(_frames(tc["joints"][-j], bad[:, -j]) for _, j in per[:4]) or "–"
        n_bad += int(bad.sum())
        sse_bad += tc["sse_bad"]
        sse_all += tc["sse_all"]
        for k in pooled:
            pooled[k] += tc[k]
        print(f"| {label} | {int(bad.sum())} | {joints} | {tc['sse_bad'] / tc['sse_all']:.0%} |")
    print(f"| all | {int(n_bad)} | | {sse_bad / sse_all:.0%} |")
    print()
    print("Pooled RMSE, cm, with and without the truth-inconsistent samples:")
    print()
    print(f"| samples | count | raw | {method} | {ONLINE} | {method} vs raw |")
    print("|---|---|---|---|---|---|")
    for name, key in (("all", "all"), ("without truth-inconsistent", "kept")):
        n, raw, est, on = pooled[key]
        n = int(n)
        print(f"| {name} | {n} | {_rms(raw, n, 2)} | {_rms(est, n, 2)} | {_rms(on, n, 2)} | "
              f"{np.sqrt(est / raw) - 1:+.0%} |")  # fmt: skip
    print()
    print(f"The raw track at the accepted glitches (raw more than {100 * threshold:.0f} cm "
          f"from the truth, not rejected by {method}):")  # fmt: skip
    print()
    print("| recording | accepted glitch samples | elbow interior angle, min ° | "
          "wrist bend, max ° | limb segment rotation rate, max rad/s | "
          f"within {100 * near:.0f} cm of another limb's accepted joint |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    tot = [0, 0]
    for label, res in results.items():
        g = res["geometry"]
        tot[0] += g["n"]
        tot[1] += g["near"]
        print(f"| {label} | {g['n']} | {_num(g['elbow_min'])} | {_num(g['wrist_max'])} | "
              f"{_num(g['rate_max'])} | {g['near']} |")  # fmt: skip
    print(f"| all | {tot[0]} | | | | {tot[1]} |")


def _rms(sse: float, n: int, digits: int = 1) -> str:
    return f"{100 * np.sqrt(sse / n):.{digits}f}" if n else "–"


def _frames(name: str, flags: np.ndarray, most: int = 3) -> str:
    """``"WristLeft 63 (frames 0–9, 117–169)"``: count and runs of flagged frames (0-based;
    the longest ``most`` runs, in time order)."""
    runs = [(a, b - 1) for _, a, b in glitch_episodes(flags[:, None])]
    shown = sorted(sorted(runs, key=lambda r: r[0] - r[1])[:most])
    text = ", ".join(f"{a}–{b}" if b > a else f"{a}" for a, b in shown)
    return f"{name} {int(flags.sum())} (frames {text}{', …' if len(runs) > most else ''})"


def _num(x: float) -> str:
    return f"{x:.0f}" if np.isfinite(x) else "–"


if __name__ == "__main__":
    sys.exit(main())

"""What smoothing can remove, against ground truth: the tracker's motion amplitude and
the error per frequency band (docs/robust.md, "Where it does not help").

For each recording (track + simultaneous mocap, paired as ``tobitkf evaluate`` does):

* the **amplitude gain** per joint group: the least-squares factor ``g`` of
  ``track − mean = g · (truth − mean)`` over the group's paired samples (each joint and
  axis centred on its own mean). ``g > 1``: the tracker reports more motion than there
  was. A zero-phase smoother that attenuates the motion then comes closer to the truth
  without removing any noise; a smoother that follows the measured motion cannot. Next
  to it the truth's motion (RMS of the centred truth per joint, 3-D): where the group
  hardly moves (less than ``MIN_MOTION``) the gain is left out, a ratio of noise.
* the **error per frequency band** (pooled over the recordings): the RMS of each
  method's error (centred per joint and axis, on each joint's longest run of frames
  where the method and the truth are both known) in the bands 0–1, 1–2.5, 2.5–5 Hz and
  above, by Parseval's identity (the bands' squares add up to the centred error's mean
  square, the "all" column).

    python tools/motion_gain.py TRACK... --truth-replace OLD NEW [--methods raw,robust,kf+rts]
"""

from __future__ import annotations

import argparse
import itertools

import numpy as np
from error_breakdown import parse_with_truth_replace  # tools/ is on the script's path

import tobitkf as tk
from tobitkf.evaluation.evaluate import evaluate_paths

#: band edges, Hz (the last band runs to the Nyquist frequency)
BANDS = (0.0, 1.0, 2.5, 5.0)
GROUPS = ("hands", "arms", "torso", "legs")
#: a joint group whose truth moves less than this (RMS about its mean, 3-D, m) gets no gain
MIN_MOTION = 0.05


def amplitude_gain(track: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """Least-squares ``g`` of ``track − mean = g · (truth − mean)`` over the samples
    where both are known, each ``(T, J, D)`` column centred on its own mean, and the
    truth's RMS motion about its means (3-D); NaN, NaN without two such samples."""
    ok = np.all(np.isfinite(track), axis=-1) & np.all(np.isfinite(truth), axis=-1)
    num = den = 0.0
    count = 0
    for j in range(track.shape[1]):
        m = ok[:, j]
        if m.sum() < 2:
            continue
        k = track[m, j] - track[m, j].mean(axis=0)
        t = truth[m, j] - truth[m, j].mean(axis=0)
        num += float(np.sum(k * t))
        den += float(np.sum(t * t))
        count += int(m.sum())
    if not count:
        return float("nan"), float("nan")
    return (num / den if den > 0 else float("nan")), float(np.sqrt(den / count))


def longest_run(ok: np.ndarray) -> slice:
    """The longest run of True in ``ok`` (an empty slice without one)."""
    best, start, best_len = slice(0, 0), None, 0
    for i, v in enumerate(np.append(ok, False)):
        if v and start is None:
            start = i
        elif not v and start is not None:
            if i - start > best_len:
                best, best_len = slice(start, i), i - start
            start = None
    return best


def band_power(err: np.ndarray, fps: float, bands=BANDS) -> tuple[np.ndarray, int]:
    """Per band, the sum over axes and frames of the centred error's power (so that the
    bands add up to ``sum((err - mean)**2)``), and the number of frames: ``err`` is
    ``(T, D)`` without NaN."""
    e = err - err.mean(axis=0)
    n = e.shape[0]
    spec = np.abs(np.fft.rfft(e, axis=0)) ** 2 / n  # Parseval: sum_k |E_k|^2 / n = sum e^2
    weight = np.full(spec.shape[0], 2.0)  # the negative frequencies
    weight[0] = 1.0
    if n % 2 == 0:
        weight[-1] = 1.0  # the Nyquist bin has no mirror
    power = (spec * weight[:, None]).sum(axis=1)
    freq = np.fft.rfftfreq(n, 1.0 / fps)
    edges = [*bands, np.inf]
    pairs = itertools.pairwise(edges)
    out = np.array([power[(freq >= lo) & (freq < hi)].sum() for lo, hi in pairs])
    return out, n


def recording(track_path: str, truth_path: str, methods: list[str]) -> dict:
    outputs: dict = {}
    gt, _ = evaluate_paths(track_path, truth_path, [m for m in methods if m != "raw"],
                           outputs=outputs)  # fmt: skip
    seq = tk.load(track_path)[0]
    outputs["raw"] = seq
    truth = gt.positions
    groups = seq.topology.joint_groups()
    paired = np.flatnonzero(gt.paired)
    gains = {}
    for g in GROUPS:
        js = [j for j in groups.get(g, []) if gt.paired[j]]
        gains[g] = amplitude_gain(seq.positions[:, js], truth[:, js]) if js else (np.nan, np.nan)
    power = {}
    for m in methods:
        est = outputs[m].positions
        tot, frames = np.zeros(len(BANDS)), 0
        for j in paired:
            ok = np.all(np.isfinite(est[:, j]), axis=-1) & np.all(np.isfinite(truth[:, j]), -1)
            run = longest_run(ok)
            if run.stop - run.start < 2:
                continue
            p, n = band_power(est[run, j] - truth[run, j], seq.fps)
            tot += p
            frames += n
        power[m] = (tot, frames)
    return {"gains": gains, "power": power}


def _gain_cell(gain: float, motion: float) -> str:
    if np.isnan(motion):
        return "–"
    if motion < MIN_MOTION:
        return f"– ({100 * motion:.0f})"
    return f"{gain:.2f} ({100 * motion:.0f})"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("tracks", nargs="+")
    ap.add_argument("--methods", default="raw,robust,kf+rts")
    args, (old, new) = parse_with_truth_replace(ap, argv)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    results = {
        t.rsplit("/", 1)[-1]: recording(t, t.replace(old, new), methods) for t in args.tracks
    }
    print("The track's motion amplitude relative to the truth's (least-squares gain, "
          "1 = as much motion as the truth; in brackets the truth's RMS motion, cm; no "
          f"gain where it is below {100 * MIN_MOTION:g} cm):")  # fmt: skip
    print()
    print("| recording | " + " | ".join(GROUPS) + " |")
    print("|---|" + "---|" * len(GROUPS))
    for label, res in results.items():
        cells = " | ".join(_gain_cell(*res["gains"][g]) for g in GROUPS)
        print(f"| {label} | {cells} |")
    print()
    names = [f"{lo:g}–{hi:g} Hz" for lo, hi in itertools.pairwise(BANDS)] + [f"> {BANDS[-1]:g} Hz"]
    print("Error per frequency band, cm RMS (centred per joint and axis; pooled over the "
          "recordings; the bands' squares add up to \"all\"):")  # fmt: skip
    print()
    print("| method | all | " + " | ".join(names) + " |")
    print("|---|---|" + "---|" * len(names))
    for m in methods:
        tot = sum(res["power"][m][0] for res in results.values())
        frames = sum(res["power"][m][1] for res in results.values())
        rms = 100 * np.sqrt(tot / frames)  # per frame: the three axes' error together
        print(
            f"| {m} | {100 * np.sqrt(tot.sum() / frames):.2f} | "
            + " | ".join(f"{v:.2f}" for v in rms)
            + " |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

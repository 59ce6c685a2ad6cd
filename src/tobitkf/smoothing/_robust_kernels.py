"""Compiled kernels of the robust smoothers (numba, ``cache=True``): the only implementation.

Imported lazily by :mod:`tobitkf.smoothing.robust` and
:mod:`tobitkf.smoothing.robust_gating` when a robust method runs, so that importing
tobitkf (and ``tobitkf --help``) does not import numba. ``NUMBA_DISABLE_JIT=1`` runs the
same code as plain Python (slow; for debugging).

Layout: only time is a loop; the bodies of a recording (and several recordings stacked
as bodies) are looped over inside the kernels. Every rule is written once, as a
*frame* function (``gate_frame``, ``confirm_frame``, ``chain_frame``, ``carry_frame``)
that updates an explicit state; the batch kernels (``*_run``) loop over time calling
them. ``online_frames`` runs ``robust_online`` over the next frames of a stream with its
state: the batch runner passes the whole recording, the live stepper one frame per
call, so live equals batch exactly. The rules and their reasons are in
:mod:`tobitkf.smoothing.robust` and docs/robust.md.

Arrays: positions ``(T, B, J, 3)`` with NaN for missing samples, masks ``(T, B, J)``,
``parents (J,)`` (-1 for roots) and ``order (J,)`` the joints sorted by depth in the tree
(roots first), so that a joint's parent is always decided before the joint itself.
"""

from __future__ import annotations

import math

import numpy as np

from tobitkf.smoothing._numba_cache import njit

_jit = njit(cache=True, nogil=True)

#: bone lengths remembered per joint by the online bone gate (median of the last ones)
BONE_WINDOW = 600
#: the online bone gate starts after this many accepted bones
BONE_MIN_COUNT = 15
#: ... or after this long, with at least BONE_MIN_EARLY of them: BONE_MIN_COUNT at 30 fps,
#: so that a stream at a lower rate is not left without a bone gate for longer
BONE_MIN_SECONDS = 0.5
BONE_MIN_EARLY = 5
#: the chain rule's same step (gate rule 3) is to within the child's bone tolerance per
#: frame of this length (30 fps, where the rule was designed): the child's own turn about
#: its parent within one frame grows with the frame's length, so a longer frame allows
#: proportionally more
CHAIN_FRAME = 1.0 / 30.0
#: the online bone length is refreshed every this many frames
BONE_REFRESH = 5
#: distinct lengths the window keeps sorted about its median (:func:`_bone_push`)
BONE_BAND = 32
# the window of one joint: val[:BONE_WINDOW] the ring, then the band, then its bounds
W_LO = BONE_WINDOW + BONE_BAND
W_HI = W_LO + 1
N_WV = W_HI + 1
# its counts (cnt[k]): lengths, next ring slot, band values, lengths below / above it
W_N = 0
W_POS = 1
W_BAND = 2
W_BELOW = 3
W_ABOVE = 4
N_W = 5

#: seconds: a duration within this of a threshold counts as equal to it (equal to
#: min_run is not longer than it, equal to max_reject is within it). Frame times summed
#: from 1/fps and stamps k/fps differ in their last bits, and a threshold of a whole
#: number of frames (min_run 0.1 s = 3 steps at 30 fps) would otherwise fall on either
#: side of a run by rounding alone (docs/robust.md, "Which choices were made on which
#: data")
TIME_EPS = 1e-9

# float state per body and joint (sf[..., k])
S_LAST_T = 0  # time of the last accepted sample (gate)
S_REJ_SINCE = 1  # start of the current rejection (gate, for max_reject)
S_L_CUR = 2  # online bone length (median of the window)
S_REJ_BEGIN = 3  # start of the current rejection stretch (confirmation)
S_CONF_BEGIN = 4  # start of the current confirmation
S_OFF_FRAME = 5  # frame of the offset a carried joint carries (online shared errors)
S_TRK_SUM = 6  # online guesses' error: sum of the squared steps between tracked samples
S_TRK_N = 7  # and their number
S_O_N = 8  # online carried samples' error: the offsets from the parent seen so far,
S_O_SUM = 9  # their sum (3: 9, 10, 11)
S_O_SS = 12  # and the sum of their squared lengths
S_L_FIRST = 13  # time of the first length in the online bone window
N_SF = 14
# rows of the online filter's state x[b, j, row] (level, velocity): the three axes, then
# the indicator filters of the shared errors (docs/robust.md)
X_CARRIED = 3  # the carried samples' shared error sd
X_GUESS = 4  # the guesses'
N_X = 5
# bool state per body and joint (sb[..., k])
B_PREV_ACC = 0  # accepted by the gate in the previous frame
B_PREV_FINAL = 1  # accepted after confirmation and chain in the previous frame
B_STARTED = 2  # the joint's filter has started
B_PREV_OK = 3  # the filter was updated with an accepted sample in the previous frame
B_PREV_INF = 4  # the previous frame's sample was INFERRED (online guesses' error)
B_HAS_GUESS = 5  # an INFERRED sample of the joint was accepted so far
B_RELEARN = 6  # online: the joint was re-locked and learns its bone length again
N_SB = 7
# parameters (pf[k])
P_MARGIN = 0
P_TOL_ABS = 1
P_TOL_REL = 2
P_MAX_REJECT = 3
P_MIN_RUN = 4
P_TAU = 5
N_PF = 6
# per-joint parameters (pj[j, k])
J_VMAX = 0
J_Q = 1  # OU velocity noise density
J_R = 2  # measurement variance
J_SD = 3  # measurement standard deviation
J_V0 = 4  # initial velocity variance
J_MIRROR = 5  # online: the joint whose bone mirrors this one's (-1: none; mirror_bones)
N_PJ = 6
# int parameters (pi[k])
I_BONES = 0
I_CARRY = 1
I_LOOKBACK = 2
I_TWO_PASS = 3
I_SHARED = 4  # online: the shared errors (carried samples, guesses) in the variance
I_MIN_PAIRS = 5  # pairs a lag of the online structure function needs
I_NDIMS = 6  # coordinates of the sequence (2: the third axis is zeros)
I_MIN_CHANGES = 7  # steps at a change of tracking state the online guesses' error needs
N_PI = 8
#: lags (frames) of the online structure function of a joint's offset from its parent;
#: a carried sample reads the smallest one at least its own lag, beyond the last one the
#: stationary limit (:func:`shared_frame`)
SF_LAGS = np.array([1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64], dtype=np.int64)
#: the ring of past offsets per joint: the longest lag + 1 frames
SF_RING = int(SF_LAGS[-1]) + 1


# ------------------------------------------------------------------------------ small
@_jit
def _dist(a0: float, a1: float, a2: float, b0: float, b1: float, b2: float) -> float:
    d0, d1, d2 = a0 - b0, a1 - b1, a2 - b2
    return math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)


@_jit
def _copy2(dst: np.ndarray, src: np.ndarray) -> None:
    """dst[...] = src for two-dimensional arrays (cheaper to compile than a slice copy)."""
    for i in range(src.shape[0]):
        for k in range(src.shape[1]):
            dst[i, k] = src[i, k]


@_jit
def _shell_path(a0: float, a1: float, a2: float, b0: float, b1: float, b2: float,
                r: float) -> float:  # fmt: skip
    """The shortest path from A to B (offsets from the parent) that keeps outside the
    ball of radius ``r`` about the parent: the straight chord, or, where the chord would
    pass closer than ``r`` (the bone shorter than it can be), the two tangents and the arc
    between them. The chord when ``r <= 0`` or A or B is not outside the ball (a bone
    already that short: no bound beyond the chord)."""
    a = _dist(a0, a1, a2, 0.0, 0.0, 0.0)
    b = _dist(b0, b1, b2, 0.0, 0.0, 0.0)
    d0, d1, d2 = b0 - a0, b1 - a1, b2 - a2
    chord = _dist(d0, d1, d2, 0.0, 0.0, 0.0)
    if not (r > 0.0 and a > r and b > r and chord > 0.0):
        return chord
    t = -(a0 * d0 + a1 * d1 + a2 * d2) / (chord * chord)
    t = min(1.0, max(0.0, t))
    if _dist(a0 + t * d0, a1 + t * d1, a2 + t * d2, 0.0, 0.0, 0.0) >= r:
        return chord
    c = min(1.0, max(-1.0, (a0 * b0 + a1 * b1 + a2 * b2) / (a * b)))
    arc = math.acos(c) - math.acos(r / a) - math.acos(r / b)
    return math.sqrt(a * a - r * r) + math.sqrt(b * b - r * r) + r * max(arc, 0.0)


@_jit
def _finite3(a0: float, a1: float, a2: float) -> bool:
    return math.isfinite(a0) and math.isfinite(a1) and math.isfinite(a2)


@_jit
def ou_coeffs(dt: float, tau: float, out: np.ndarray) -> None:
    """``out = (a01, a11, q00, q01, q11)``: transition ``[[1, a01], [0, a11]]`` and unit-q
    process noise of the integrated OU velocity model over one step ``dt`` (exact
    discretisation; ``tau = inf`` is the constant-velocity model)."""
    if not math.isfinite(tau):
        out[0] = dt
        out[1] = 1.0
        out[2] = dt**3 / 3
        out[3] = dt**2 / 2
        out[4] = dt
        return
    rho = math.exp(-dt / tau)
    om = -math.expm1(-dt / tau)  # 1 - rho, accurate for small steps
    om2 = -math.expm1(-2 * dt / tau)  # 1 - rho^2
    out[0] = tau * om
    out[1] = rho
    if dt < 1e-3 * tau:  # Q_xx cancels for dt << tau: the series dt^3/3 - dt^4/(4 tau)
        out[2] = dt**3 / 3 - dt**4 / (4 * tau)
    else:
        out[2] = tau**2 * (dt - 2 * tau * om + 0.5 * tau * om2)
    out[3] = 0.5 * tau**2 * om**2
    out[4] = 0.5 * tau * om2


@_jit
def ou_table(steps: np.ndarray, tau: float) -> np.ndarray:
    """``(T, 5)`` coefficients of :func:`ou_coeffs` for every step."""
    T = steps.shape[0]
    out = np.empty((T, 5))
    for t in range(T):
        ou_coeffs(steps[t], tau, out[t])
    return out


# ------------------------------------------------------------------------------ bones
@_jit
def _band_at(val: np.ndarray, j: int, m: int, v: float) -> int:
    """Index of the first of joint ``j``'s ``m`` sorted band values not below ``v``
    (``m``: none)."""
    lo, hi = 0, m
    while lo < hi:
        mid = (lo + hi) // 2
        if val[j, BONE_WINDOW + mid] < v:
            lo = mid + 1
        else:
            hi = mid
    return lo


@_jit
def _band_put(val: np.ndarray, mult: np.ndarray, cnt: np.ndarray, j: int, v: float) -> None:
    """One more copy of ``v`` (within the bounds) in joint ``j``'s band, which has room."""
    m = cnt[j, W_BAND]
    i = _band_at(val, j, m, v)
    if i < m and val[j, BONE_WINDOW + i] == v:
        mult[j, i] += 1
        return
    for s in range(m, i, -1):
        val[j, BONE_WINDOW + s] = val[j, BONE_WINDOW + s - 1]
        mult[j, s] = mult[j, s - 1]
    val[j, BONE_WINDOW + i] = v
    mult[j, i] = 1
    cnt[j, W_BAND] = m + 1


@_jit
def _band_add(val: np.ndarray, mult: np.ndarray, cnt: np.ndarray, j: int, v: float) -> None:
    """Put ``v`` (within the bounds) in joint ``j``'s band; a full band first hands its
    distinct value farthest from the median (with its copies) to the count of its side,
    and ``v`` may then fall outside."""
    m = cnt[j, W_BAND]
    if m == BONE_BAND:
        i = _band_at(val, j, m, v)
        if not (i < m and val[j, BONE_WINDOW + i] == v):
            inside = cnt[j, W_N] - 1 - cnt[j, W_BELOW] - cnt[j, W_ABOVE]  # v not counted
            if 2 * ((cnt[j, W_N] - 1) // 2 - cnt[j, W_BELOW]) < inside:  # median: lower half
                cnt[j, W_ABOVE] += mult[j, m - 1]
                val[j, W_HI] = val[j, BONE_WINDOW + m - 2]
            else:
                cnt[j, W_BELOW] += mult[j, 0]
                for s in range(m - 1):
                    val[j, BONE_WINDOW + s] = val[j, BONE_WINDOW + s + 1]
                    mult[j, s] = mult[j, s + 1]
                val[j, W_LO] = val[j, BONE_WINDOW]
            cnt[j, W_BAND] = m - 1
            if v < val[j, W_LO]:
                cnt[j, W_BELOW] += 1
                return
            if v > val[j, W_HI]:
                cnt[j, W_ABOVE] += 1
                return
    _band_put(val, mult, cnt, j, v)


@_jit
def _window_reset(val: np.ndarray, cnt: np.ndarray, j: int) -> None:
    """Empty joint ``j``'s window (its first lengths all go into the band)."""
    for k in range(N_W):
        cnt[j, k] = 0
    val[j, W_LO] = -math.inf
    val[j, W_HI] = math.inf


@_jit
def _bone_push(val: np.ndarray, mult: np.ndarray, cnt: np.ndarray, j: int, v: float) -> None:
    """Append ``v`` to joint ``j``'s window of bone lengths (the oldest leaves when full).

    ``val[j, :BONE_WINDOW]`` is the ring of lengths in arrival order (``cnt[j, W_N]`` of
    them, the next one written at ``cnt[j, W_POS]``). The median is read off the *band*:
    the distinct lengths between the bounds ``val[j, W_LO]`` and ``val[j, W_HI]``, sorted
    in ``val[j, BONE_WINDOW:]`` (``cnt[j, W_BAND]`` of them, their multiplicities in
    ``mult[j]``); the lengths below and above it are only counted (``cnt[j, W_BELOW]``,
    ``cnt[j, W_ABOVE]``). Most lengths fall outside the band, so a push is mostly two
    counts (:func:`gate_frame` does those itself: a call with array arguments costs
    atomic reference counts, more than the push); :func:`_window_median` rebuilds the
    band about the median from the ring when the median has left it."""
    n = cnt[j, W_N]
    pos = cnt[j, W_POS]
    lo = val[j, W_LO]
    hi = val[j, W_HI]
    if n == BONE_WINDOW:
        old = val[j, pos]
        if old < lo:
            cnt[j, W_BELOW] -= 1
        elif old > hi:
            cnt[j, W_ABOVE] -= 1
        else:  # one copy of it out of the band
            m = cnt[j, W_BAND]
            i = _band_at(val, j, m, old)
            mult[j, i] -= 1
            if mult[j, i] == 0:
                for s in range(i, m - 1):
                    val[j, BONE_WINDOW + s] = val[j, BONE_WINDOW + s + 1]
                    mult[j, s] = mult[j, s + 1]
                cnt[j, W_BAND] = m - 1
    else:
        cnt[j, W_N] = n + 1
    val[j, pos] = v
    cnt[j, W_POS] = pos + 1 if pos + 1 < BONE_WINDOW else 0
    if v < lo:
        cnt[j, W_BELOW] += 1
    elif v > hi:
        cnt[j, W_ABOVE] += 1
    else:
        _band_add(val, mult, cnt, j, v)


@_jit
def _window_median(val: np.ndarray, mult: np.ndarray, cnt: np.ndarray, j: int) -> float:
    """Median of joint ``j``'s window of lengths (:func:`_bone_push`) as np.median takes
    it (the mean of the two middle lengths for an even count). When a middle rank is not
    in the band, the band is first rebuilt from the ring: the lengths from
    ``BONE_BAND // 2 - 2`` ranks below the middle ones to as many above."""
    n = cnt[j, W_N]
    k = (n - 1) // 2
    upper = n // 2  # the upper middle rank (k for an odd count)
    if k < cnt[j, W_BELOW] or upper >= n - cnt[j, W_ABOVE]:
        buf = val[j, :n].copy()
        lo_r = max(k - BONE_BAND // 2 + 2, 0)
        hi_r = min(upper + BONE_BAND // 2 - 2, n - 1)
        lo = val[j, W_LO] = _select(buf, 0, n - 1, lo_r)
        hi = val[j, W_HI] = _select(buf, lo_r, n - 1, hi_r)
        cnt[j, W_BAND] = cnt[j, W_BELOW] = cnt[j, W_ABOVE] = 0
        for s in range(n):
            v = val[j, s]
            if v < lo:
                cnt[j, W_BELOW] += 1
            elif v > hi:
                cnt[j, W_ABOVE] += 1
            else:
                _band_put(val, mult, cnt, j, v)
    r = k - cnt[j, W_BELOW]  # the band's value of rank r, counting copies
    i = 0
    while r >= mult[j, i]:
        r -= mult[j, i]
        i += 1
    a = val[j, BONE_WINDOW + i]
    if upper == k:
        return a
    return (a + (a if r + 1 < mult[j, i] else val[j, BONE_WINDOW + i + 1])) / 2


@_jit
def _select(a: np.ndarray, lo: int, hi: int, k: int) -> float:
    """The ``k``-th smallest of ``a[lo:hi + 1]`` (``lo <= k <= hi``), left at ``a[k]`` with
    nothing larger before it and nothing smaller after it (within ``lo..hi``).

    Quickselect whose partitions do not branch on the data (a swap every element and a
    counter moved by the comparison: on lengths scattered about their median a branch
    per element is mispredicted half the time). The values equal to the pivot are
    gathered by a second pass, so many equal values (hierarchy-converted skeletons) cost
    nothing."""
    while lo < hi:
        mid = (lo + hi) // 2
        p0, p1, p2 = a[lo], a[mid], a[hi]
        pivot = max(min(p0, p1), min(max(p0, p1), p2))  # median of three
        lt = lo  # a[lo:lt] < pivot
        for i in range(lo, hi + 1):
            v = a[i]
            a[i] = a[lt]
            a[lt] = v
            lt += v < pivot
        if k < lt:
            hi = lt - 1
            continue
        eq = lt  # a[lt:eq] == pivot (a[lt:] are not smaller)
        for i in range(lt, hi + 1):
            v = a[i]
            a[i] = a[eq]
            a[eq] = v
            eq += v == pivot
        if k < eq:
            return pivot
        lo = eq
    return a[k]


@_jit
def _median(a: np.ndarray, n: int) -> float:
    """Median of ``a[:n]`` as np.median takes it (the mean of the two middle values for
    even n); reorders ``a[:n]``."""
    k = (n - 1) // 2
    mid = _select(a, 0, n - 1, k)
    # a[k] is the k-th smallest, everything after it is not smaller
    if n % 2 == 1:
        return mid
    upper = a[k + 1]
    for i in range(k + 2, n):
        upper = min(upper, a[i])
    return (mid + upper) / 2


@_jit
def bone_lengths_run(pos: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """Median over frames of each joint's distance to its parent, ``(B, J)`` (NaN for
    roots and for bones never seen: frames with a non-finite end are left out). Frames
    are the outer loop (one contiguous read each), the lengths gathered per bone."""
    T, B, J = pos.shape[0], pos.shape[1], pos.shape[2]
    out = np.full((B, J), np.nan)
    buf = np.empty((B, J, T))
    cnt = np.zeros((B, J), dtype=np.int64)
    for t in range(T):
        for b in range(B):
            for j in range(J):
                p = parents[j]
                if p < 0:
                    continue
                d = _dist(pos[t, b, j, 0], pos[t, b, j, 1], pos[t, b, j, 2],
                          pos[t, b, p, 0], pos[t, b, p, 1], pos[t, b, p, 2])  # fmt: skip
                if math.isfinite(d):
                    buf[b, j, cnt[b, j]] = d
                    cnt[b, j] += 1
    for b in range(B):
        for j in range(J):
            if cnt[b, j] > 0:
                out[b, j] = _median(buf[b, j], cnt[b, j])
    return out


# ------------------------------------------------------------------------------ gate
@_jit
def gate_frame(
    y: np.ndarray,  # (J, 3) this frame, NaN = missing
    yprev: np.ndarray,  # (J, 3) previous frame (ignored when not has_prev)
    guess: np.ndarray,  # (J,) the frame's INFERRED samples (no witness for the blame)
    has_prev: bool,
    tt: float,
    dt_prev: float,  # tt - time of the previous frame
    tidx: int,  # frame index (the online bone length is refreshed every BONE_REFRESH)
    parents: np.ndarray,
    order: np.ndarray,
    pj: np.ndarray,
    pf: np.ndarray,
    L_fixed: np.ndarray,  # (J,) offline bone lengths (NaN = no check)
    use_bones: bool,
    online: bool,  # bone lengths learnt from the accepted frames so far
    mirror: bool,  # online, 3-D: the mirror rule (pj[:, J_MIRROR])
    max_reject: float,
    last: np.ndarray,  # state (J, 3): last accepted sample
    sf: np.ndarray,  # state (J, N_SF)
    sb: np.ndarray,  # state (J, N_SB)
    h_val: np.ndarray,  # state (J, N_WV): bone-length windows (_bone_push)
    h_mult: np.ndarray,  # state (J, BONE_BAND)
    h_cnt: np.ndarray,  # state (J, N_W)
    acc: np.ndarray,  # out (J,) accepted
) -> None:
    """Speed gate, bone gate, chain rule and re-acquisition for one frame (rules 1-4)."""
    J = parents.shape[0]
    margin = pf[P_MARGIN]
    tol_abs = pf[P_TOL_ABS]
    tol_rel = pf[P_TOL_REL]
    if online and use_bones and tidx % BONE_REFRESH == 0:
        for j in range(J):
            n = h_cnt[j, W_N]
            if n >= BONE_MIN_COUNT or (
                n >= BONE_MIN_EARLY and tt - sf[j, S_L_FIRST] >= BONE_MIN_SECONDS
            ):
                sf[j, S_L_CUR] = _window_median(h_val, h_mult, h_cnt, j)
    # the bone gate's blame (rule 2): a joint whose bones to two or more of its children
    # are broken while those children went on as before (accepted last frame, their own
    # step inside their speed gate, their bone to where the joint was last accepted
    # intact) is the one that failed: one failure, not two. It counts where the joint's
    # step starts the break, and while its rejection lasts. A child the sensor only
    # guessed (INFERRED) is no witness
    blame = np.zeros(J, dtype=np.int64)
    if use_bones and has_prev:
        # a child counts only if it has children of its own: the end of a chain (a
        # hand tip, a thumb) is where trackers place joints worst
        inner = np.zeros(J, dtype=np.bool_)
        for g in range(J):
            if parents[g] >= 0:
                inner[parents[g]] = True
        for c in range(J):
            p = parents[c]
            if p < 0 or not sb[c, B_PREV_ACC] or not inner[c] or guess[c]:
                continue
            Lc = sf[c, S_L_CUR] if online else L_fixed[c]
            if not math.isfinite(Lc):
                continue
            if not (_finite3(y[c, 0], y[c, 1], y[c, 2]) and _finite3(y[p, 0], y[p, 1], y[p, 2])
                    and _finite3(yprev[c, 0], yprev[c, 1], yprev[c, 2])):  # fmt: skip
                continue
            tol_c = tol_abs + tol_rel * Lc
            if _dist(y[c, 0], y[c, 1], y[c, 2], yprev[c, 0], yprev[c, 1], yprev[c, 2]) > (
                    pj[c, J_VMAX] * dt_prev + margin):  # fmt: skip
                continue
            blen_c = _dist(y[c, 0], y[c, 1], y[c, 2], y[p, 0], y[p, 1], y[p, 2])
            if not (abs(blen_c - Lc) > tol_c):
                continue
            # ... and kept to where the parent was last accepted: the parent's move broke it
            # (where the parent was accepted last frame, its step starts the break)
            if not (abs(_dist(y[c, 0], y[c, 1], y[c, 2], last[p, 0], last[p, 1], last[p, 2])
                        - Lc) <= tol_c):  # fmt: skip
                continue
            if not sb[p, B_PREV_ACC] and not (tt - sf[p, S_REJ_SINCE] <= max_reject + TIME_EPS):
                # the parent's rejection goes on past max_reject: no lock-out
                continue
            blame[p] += 1
    for k in range(J):
        j = order[k]
        p = parents[j]
        is_root = p < 0
        pp = 0 if is_root else p
        vmax = pj[j, J_VMAX]
        valid = _finite3(y[j, 0], y[j, 1], y[j, 2])
        d = _dist(y[j, 0], y[j, 1], y[j, 2], last[j, 0], last[j, 1], last[j, 2])
        last_t = sf[j, S_LAST_T]
        gate = vmax * (tt - last_t) + margin
        gate_ok = (not math.isfinite(last_t)) or (d <= gate)
        step_ok = sb[j, B_PREV_ACC] and (d <= vmax * dt_prev + margin)
        relock = False
        if has_prev:
            raw_step = _dist(y[j, 0], y[j, 1], y[j, 2], yprev[j, 0], yprev[j, 1], yprev[j, 2])
            relock = (tt - sf[j, S_REJ_SINCE] > max_reject + TIME_EPS) and (
                raw_step <= vmax * dt_prev + margin
            )
        # a missing parent is no evidence against the joint (only a rejected one is)
        parent_acc = is_root or acc[p] or not _finite3(y[pp, 0], y[pp, 1], y[pp, 2])
        bone_ok = True
        blen = math.nan
        Lj = math.nan
        if use_bones:
            blen = _dist(y[j, 0], y[j, 1], y[j, 2], y[pp, 0], y[pp, 1], y[pp, 2])
            Lj = sf[j, S_L_CUR] if online else L_fixed[j]
            if online and mirror and not math.isfinite(Lj) and not sb[j, B_RELEARN]:
                # no length learnt yet (the stream's first frames): the other side's
                # bone, once learnt, stands in for it (a body's two sides have the same
                # bones). Not after a re-lock, which trusts the measurement
                m = int(pj[j, J_MIRROR])
                if m >= 0:
                    Lj = sf[m, S_L_CUR]
        tol = tol_abs + tol_rel * Lj  # NaN without a bone length (yet): no bone rule
        if use_bones:
            bone_ok = is_root or (not math.isfinite(Lj)) or (not (abs(blen - Lj) > tol))
            m = int(pj[j, J_MIRROR]) if mirror and not bone_ok else -1
            if m >= 0:
                # the mirror rule: when the length learnt for the other side's bone
                # disagrees with this one's (learnt while the limb was failing, at the
                # stream's start), it is a second reference
                Lm = sf[m, S_L_CUR]
                if math.isfinite(Lm) and abs(Lj - Lm) > tol_abs + tol_rel * min(Lj, Lm):
                    bone_ok = not (abs(blen - Lm) > tol_abs + tol_rel * Lm)
        if (has_prev and not is_root and sb[j, B_PREV_ACC] and math.isfinite(tol)
                and _finite3(yprev[pp, 0], yprev[pp, 1], yprev[pp, 2])
                and _finite3(y[pp, 0], y[pp, 1], y[pp, 2])
                and _finite3(yprev[j, 0], yprev[j, 1], yprev[j, 2])):  # fmt: skip
            # the path of the step (rule 1, the bone kept): a bone does not shrink below
            # the shortest length the bone gate accepts, so about its parent the joint
            # went around, not across, that ball; what the parent moved may have carried
            # it part of the way. The step was accepted last frame, so the speed gate
            # is this step's.
            path = _shell_path(
                yprev[j, 0] - yprev[pp, 0],
                yprev[j, 1] - yprev[pp, 1],
                yprev[j, 2] - yprev[pp, 2],
                y[j, 0] - y[pp, 0],
                y[j, 1] - y[pp, 1],
                y[j, 2] - y[pp, 2],
                Lj - tol,
            ) - _dist(y[pp, 0], y[pp, 1], y[pp, 2], yprev[pp, 0], yprev[pp, 1], yprev[pp, 2])
            if path > vmax * dt_prev + margin:
                step_ok = False
                gate_ok = False
        if step_ok and not parent_acc and has_prev and sb[pp, B_PREV_ACC]:
            # the parent's rejection starts at this step: a joint that made the same step
            # (to within its bone's tolerance per 30 fps frame; a parent's step larger
            # than the tolerance) kept its bone to the parent's impossible place, so it
            # shares the failure
            dp0 = y[pp, 0] - yprev[pp, 0]
            dp1 = y[pp, 1] - yprev[pp, 1]
            dp2 = y[pp, 2] - yprev[pp, 2]
            d_own = _dist(y[j, 0] - yprev[j, 0], y[j, 1] - yprev[j, 1], y[j, 2] - yprev[j, 2],
                          dp0, dp1, dp2)  # fmt: skip
            same = tol * max(1.0, dt_prev / CHAIN_FRAME)
            if _dist(dp0, dp1, dp2, 0.0, 0.0, 0.0) > tol and d_own <= same:
                step_ok = False
        ok = valid and ((gate_ok and (bone_ok if parent_acc else step_ok)) or relock)
        if blame[j] >= 2:
            ok = False
        acc[j] = ok
        if online and use_bones:
            # a re-lock means the learnt bone length was wrong: learn it again
            if relock and not (gate_ok and bone_ok and parent_acc):
                _window_reset(h_val, h_cnt, j)
                sf[j, S_L_CUR] = math.nan
                sb[j, B_RELEARN] = True
            if ok and not is_root and acc[p]:
                # the usual push, done here: the new length and the leaving one outside
                # the band (_bone_push), only counted
                n, pos = h_cnt[j, W_N], h_cnt[j, W_POS]
                if n == 0:  # the window's first length (again after a re-lock)
                    sf[j, S_L_FIRST] = tt
                lo, hi = h_val[j, W_LO], h_val[j, W_HI]
                old = h_val[j, pos]
                full = n == BONE_WINDOW
                if (blen < lo or blen > hi) and not (full and lo <= old <= hi):
                    if full:
                        h_cnt[j, W_BELOW if old < lo else W_ABOVE] -= 1
                    else:
                        h_cnt[j, W_N] = n + 1
                    h_val[j, pos] = blen
                    h_cnt[j, W_POS] = pos + 1 if pos + 1 < BONE_WINDOW else 0
                    h_cnt[j, W_BELOW if blen < lo else W_ABOVE] += 1
                else:
                    _bone_push(h_val, h_mult, h_cnt, j, blen)
    for j in range(J):
        a = acc[j]
        if a:
            last[j, 0] = y[j, 0]
            last[j, 1] = y[j, 1]
            last[j, 2] = y[j, 2]
            sf[j, S_LAST_T] = tt
            sf[j, S_REJ_SINCE] = math.nan
        elif _finite3(y[j, 0], y[j, 1], y[j, 2]) and math.isnan(sf[j, S_REJ_SINCE]):
            sf[j, S_REJ_SINCE] = tt
        sb[j, B_PREV_ACC] = a


def new_state(B: int, J: int, lookback: int, shared: bool = False) -> tuple:
    """The state of ``B`` bodies of ``J`` joints before their first frame (plain numpy:
    nothing to compile); ``shared``: with the online structure function's ring of
    offsets (:func:`shared_frame`), else empty."""
    K = lookback + 1
    last = np.full((B, J, 3), np.nan)
    yprev = np.full((B, J, 3), np.nan)
    off = np.full((B, J, 3), np.nan)
    sf = np.full((B, J, N_SF), np.nan)
    sb = np.zeros((B, J, N_SB), dtype=np.bool_)
    h_val = np.zeros((B, J, N_WV))
    h_val[..., W_LO], h_val[..., W_HI] = -np.inf, np.inf  # empty windows (_window_reset)
    h_mult = np.zeros((B, J, BONE_BAND), dtype=np.int64)
    h_cnt = np.zeros((B, J, N_W), dtype=np.int64)
    x = np.zeros((B, J, N_X, 2))
    P = np.zeros((B, J, 2, 2))
    xs_h = np.zeros((K, B, J, N_X, 2))
    Ps_h = np.zeros((K, B, J, 4))  # p00, p01, p10, p11
    ok_h = np.zeros((K, B, J), dtype=np.bool_)
    coef_h = np.zeros((K, 5))
    clock = np.zeros(2)  # frames seen, time of the last frame
    # online shared errors (few arrays: each is typed at every live call): the ring of
    # past offsets from the parent (NaN = not known), the structure function's sums and
    # pair counts per lag; per body, the sum of the squared steps at a change of tracking
    # state and their number (the indicator filters are rows of x, the running sums in sf)
    R = SF_RING if shared else 0
    o_ring = np.full((B, R, J, 3), np.nan)
    s_acc = np.zeros((B, 2, SF_LAGS.size, J))
    g_stat = np.zeros((B, 2))
    for k in (S_TRK_SUM, S_TRK_N, S_O_N, S_O_SUM, S_O_SUM + 1, S_O_SUM + 2, S_O_SS):
        sf[..., k] = 0.0
    return (last, yprev, off, sf, sb, h_val, h_mult, h_cnt, x, P, xs_h, Ps_h, ok_h, coef_h,
            clock, o_ring, s_acc, g_stat)  # fmt: skip


def new_work(B: int, J: int) -> tuple:
    """Work arrays of :func:`online_frames` (``scratch``, ``scratch1``, ``acc``)."""
    return np.empty((4, J, 3)), np.full((4, J), np.nan), np.zeros((3, B, J), dtype=np.bool_)


@_jit
def gate_both(
    ys: np.ndarray,
    times: np.ndarray,
    times_back: np.ndarray,  # -times[::-1]: the backward pass's clock
    parents: np.ndarray,
    order: np.ndarray,
    pj: np.ndarray,
    pf: np.ndarray,
    L_fixed: np.ndarray,  # (B, J)
    guess: np.ndarray,  # (T, B, J) the INFERRED samples
    use_bones: bool,
    max_reject: float,
    two_pass: bool,
    st: tuple,  # new_state(B, J, 0)
    st_back: tuple,  # another, for the backward pass
) -> np.ndarray:
    """The offline gate: forwards in time and (``two_pass``) backwards, a sample accepted
    when both passes accept it, ``(T, B, J)``. The backward pass is the forward one on
    the time-reversed recording (clock ``times_back``), read in place."""
    T, B, J = ys.shape[0], ys.shape[1], ys.shape[2]
    acc = np.zeros((T, B, J), dtype=np.bool_)
    gate_pass(ys, times, parents, order, pj, pf, L_fixed, guess, use_bones, False,
              max_reject, st, False, acc)  # fmt: skip
    if two_pass:
        gate_pass(ys, times_back, parents, order, pj, pf, L_fixed, guess, use_bones, False,
                  max_reject, st_back, True, acc)  # fmt: skip
    return acc


@_jit
def gate_pass(
    ys: np.ndarray,
    times: np.ndarray,  # the pass's clock: frame i of the pass is at times[i]
    parents: np.ndarray,
    order: np.ndarray,
    pj: np.ndarray,
    pf: np.ndarray,
    L_fixed: np.ndarray,
    guess: np.ndarray,  # (T, B, J) the INFERRED samples
    use_bones: bool,
    online: bool,
    max_reject: float,
    st: tuple,
    reverse: bool,  # frame i of the pass is frame T - 1 - i, and acc is ANDed
    acc: np.ndarray,  # out (T, B, J)
) -> None:
    """Causal accept / reject decision (gate rules 1-4) for every sample into ``acc``:
    :func:`gate_frame` over time, frames outside and bodies inside (a frame of every
    body is one contiguous read)."""
    T, B, J = ys.shape[0], ys.shape[1], ys.shape[2]
    last, sf, sb, h_val, h_mult, h_cnt = st[0], st[3], st[4], st[5], st[6], st[7]
    out = np.empty((B, J), dtype=np.bool_)
    for i in range(T):
        t = T - 1 - i if reverse else i
        has_prev = i > 0
        dt_prev = times[i] - times[i - 1] if has_prev else math.inf
        tp = t
        if has_prev:
            tp = t + 1 if reverse else t - 1
        for b in range(B):
            gate_frame(ys[t, b], ys[tp, b], guess[t, b], has_prev, times[i], dt_prev, i,
                       parents, order, pj, pf, L_fixed[b], use_bones, online, False,
                       max_reject, last[b], sf[b], sb[b], h_val[b], h_mult[b], h_cnt[b],
                       out[b])  # fmt: skip
        if reverse:
            for b in range(B):
                for j in range(J):
                    acc[t, b, j] = acc[t, b, j] and out[b, j]
        else:
            for b in range(B):
                for j in range(J):
                    acc[t, b, j] = out[b, j]


# ------------------------------------------------------------------------------ offline rules
@_jit
def drop_short_runs_run(
    acc: np.ndarray, rejected: np.ndarray, times: np.ndarray, min_run: float
) -> np.ndarray:
    """Accepted runs not longer than ``min_run`` between two rejections are rejected."""
    out = acc.copy()
    T, B, J = acc.shape[0], acc.shape[1], acc.shape[2]
    if T < 3 or min_run <= 0:
        return out
    nxt = np.empty(T + 1, dtype=np.int8)  # status of the first non-missing sample >= t
    for b in range(B):
        for j in range(J):
            nxt[T] = -1  # none
            for t in range(T - 1, -1, -1):
                if rejected[t, b, j]:
                    nxt[t] = 1
                elif acc[t, b, j]:
                    nxt[t] = 0
                else:
                    nxt[t] = nxt[t + 1]
            before = -1  # status of the last non-missing sample before t
            t = 0
            while t < T:
                if not acc[t, b, j]:
                    if rejected[t, b, j]:
                        before = 1
                    t += 1
                    continue
                s = t
                while t < T and acc[t, b, j]:
                    t += 1
                e = t  # the run is [s, e)
                if s > 0 and e < T and before == 1 and nxt[e] == 1:
                    if times[e - 1] - times[s] < min_run + TIME_EPS:
                        for i in range(s, e):
                            out[i, b, j] = False
                before = 0
    return out


@_jit
def chain_frame(
    out_t: np.ndarray,  # (J,) accept mask of frame t, updated
    out_s: np.ndarray,  # (J,) accept mask of the neighbouring frame s
    y_t: np.ndarray,
    y_s: np.ndarray,
    dt: float,  # |time t - time s|
    parents: np.ndarray,
    order: np.ndarray,
    pj: np.ndarray,
    margin: float,
) -> None:
    """The chain rule on a combined mask: a joint whose parent is rejected (present but
    not accepted; a missing parent says nothing) stays accepted only if it was accepted
    in the neighbouring frame and did not jump from it (its speed part: the shared step
    at the start of a parent's rejection was judged in the gate passes)."""
    for k in range(order.shape[0]):
        j = order[k]
        p = parents[j]
        if p < 0 or not out_t[j] or out_t[p] or not _finite3(y_t[p, 0], y_t[p, 1], y_t[p, 2]):
            continue
        moved = _dist(y_t[j, 0], y_t[j, 1], y_t[j, 2], y_s[j, 0], y_s[j, 1], y_s[j, 2])
        if not (out_s[j] and moved <= pj[j, J_VMAX] * dt + margin):
            out_t[j] = False


@_jit
def enforce_chain_run(
    acc: np.ndarray,
    ys: np.ndarray,
    times: np.ndarray,
    parents: np.ndarray,
    order: np.ndarray,
    pj: np.ndarray,
    margin: float,
    backward: bool,
) -> np.ndarray:
    """:func:`chain_frame` forwards in time, then (``backward``) backwards."""
    out = acc.copy()
    T, B = acc.shape[0], acc.shape[1]
    for b in range(B):
        for t in range(1, T):
            chain_frame(out[t, b], out[t - 1, b], ys[t, b], ys[t - 1, b],
                        abs(times[t] - times[t - 1]), parents, order, pj, margin)  # fmt: skip
        if backward:
            for t in range(T - 2, -1, -1):
                chain_frame(out[t, b], out[t + 1, b], ys[t, b], ys[t + 1, b],
                            abs(times[t] - times[t + 1]), parents, order, pj, margin)  # fmt: skip
    return out


# ------------------------------------------------------------------------------ online rules
@_jit
def confirm_frame(
    acc_t: np.ndarray,  # (J,) gate decision of this frame
    missing_t: np.ndarray,
    tt: float,
    min_run: float,
    sf: np.ndarray,  # state (J, N_SF)
    out_t: np.ndarray,  # (J,) confirmed decision
) -> None:
    """After a rejection longer than ``min_run``, a joint is believed again only once
    its measurements have passed the gates for longer than ``min_run``."""
    for j in range(acc_t.shape[0]):
        out_t[j] = acc_t[j]
        if missing_t[j]:
            continue
        if not acc_t[j]:
            # a rejection starts a stretch, or continues it and cancels its confirmation
            if math.isnan(sf[j, S_REJ_BEGIN]):
                sf[j, S_REJ_BEGIN] = tt
            sf[j, S_CONF_BEGIN] = math.nan
            continue
        if math.isfinite(sf[j, S_REJ_BEGIN]) and math.isnan(sf[j, S_CONF_BEGIN]):
            # the first accepted sample after a stretch: a long stretch needs confirmation
            if tt - sf[j, S_REJ_BEGIN] >= min_run + TIME_EPS:
                sf[j, S_CONF_BEGIN] = tt
            else:
                sf[j, S_REJ_BEGIN] = math.nan
        if math.isfinite(sf[j, S_CONF_BEGIN]):
            if tt - sf[j, S_CONF_BEGIN] < min_run + TIME_EPS:
                out_t[j] = False
            else:
                sf[j, S_CONF_BEGIN] = math.nan
                sf[j, S_REJ_BEGIN] = math.nan


@_jit
def confirm_run(
    acc: np.ndarray, missing: np.ndarray, times: np.ndarray, min_run: float
) -> np.ndarray:
    """:func:`confirm_frame` over time, ``(T, B, J)``."""
    T, B, J = acc.shape[0], acc.shape[1], acc.shape[2]
    out = acc.copy()
    if min_run <= 0:
        return out
    sf = np.full((B, J, N_SF), np.nan)
    for b in range(B):
        for t in range(T):
            confirm_frame(acc[t, b], missing[t, b], times[t], min_run, sf[b], out[t, b])
    return out


# ------------------------------------------------------------------------------ inferred bones
@_jit
def project_frame(
    y: np.ndarray,  # (J, 3) this frame, NaN = missing
    inferred: np.ndarray,  # (J,) the sensor guessed the joint (INFERRED)
    parents: np.ndarray,
    order: np.ndarray,
    L: np.ndarray,  # (J,) bone lengths (NaN = unknown: the joint is left as it is)
    out: np.ndarray,  # out (J, 3): y with the inferred joints moved
    shift: np.ndarray,  # scratch (J, 3): how far each joint was moved
) -> None:
    """Inferred joints put back at their bone's length: an INFERRED joint keeps its
    direction from its parent (as placed by the parent's own correction) but moves to
    the distance ``L`` from it. An inferred joint whose parent is inferred too first
    moves with the parent's correction (the sensor guessed the chain as a whole).
    Tracked and missing joints and roots are copied unchanged; an inferred joint whose
    parent position or length is unknown only moves with its parent's correction."""
    J = parents.shape[0]
    for k in range(J):
        j = order[k]
        p = parents[j]
        for i in range(3):
            out[j, i] = y[j, i]
            shift[j, i] = 0.0
        if p < 0 or not inferred[j] or not _finite3(y[j, 0], y[j, 1], y[j, 2]):
            continue
        if inferred[p]:
            for i in range(3):
                out[j, i] += shift[p, i]
        d = _dist(out[j, 0], out[j, 1], out[j, 2], out[p, 0], out[p, 1], out[p, 2])
        if math.isfinite(L[j]) and math.isfinite(d) and d > 0.0:
            s = L[j] / d
            for i in range(3):
                out[j, i] = out[p, i] + (out[j, i] - out[p, i]) * s
        for i in range(3):
            shift[j, i] = out[j, i] - y[j, i]


@_jit
def project_run(
    ys: np.ndarray,  # (T, B, J, 3)
    inferred: np.ndarray,  # (T, B, J)
    parents: np.ndarray,
    order: np.ndarray,
    L: np.ndarray,  # (B, J)
) -> np.ndarray:
    """:func:`project_frame` over a recording: a new ``(T, B, J, 3)`` array."""
    T, B, J = ys.shape[0], ys.shape[1], ys.shape[2]
    out = np.empty((T, B, J, 3))
    shift = np.empty((J, 3))
    for t in range(T):
        for b in range(B):
            project_frame(ys[t, b], inferred[t, b], parents, order, L[b], out[t, b], shift)
    return out


# ------------------------------------------------------------------------------ carrying
@_jit
def carry_frame(
    y: np.ndarray,  # (J, 3)
    acc: np.ndarray,  # (J,)
    parents: np.ndarray,
    order: np.ndarray,
    off: np.ndarray,  # state (J, 3): offset from the parent when both were last accepted
    anchor: np.ndarray,  # scratch (J, 3)
    pseudo: np.ndarray,  # out (J, 3), NaN where none
    radius: np.ndarray,  # out (J,), NaN where none
) -> None:
    """A rejected joint placed at its parent (measured or itself carried) plus its last
    good offset from it; ``radius`` is the offset's length."""
    J = parents.shape[0]
    for j in range(J):
        for a in range(3):
            anchor[j, a] = y[j, a] if acc[j] else math.nan
            pseudo[j, a] = math.nan
        radius[j] = math.nan
    for k in range(J):
        j = order[k]
        p = parents[j]
        if p < 0:
            continue
        if _finite3(y[j, 0], y[j, 1], y[j, 2]) and not acc[j]:
            c0 = anchor[p, 0] + off[j, 0]
            c1 = anchor[p, 1] + off[j, 1]
            c2 = anchor[p, 2] + off[j, 2]
            if math.isfinite(c0) and math.isfinite(c1) and math.isfinite(c2):
                pseudo[j, 0] = anchor[j, 0] = c0
                pseudo[j, 1] = anchor[j, 1] = c1
                pseudo[j, 2] = anchor[j, 2] = c2
                radius[j] = _dist(off[j, 0], off[j, 1], off[j, 2], 0.0, 0.0, 0.0)
        if acc[j] and acc[p]:
            for a in range(3):
                off[j, a] = y[j, a] - y[p, a]


@_jit
def carry_run(
    ys: np.ndarray, acc: np.ndarray, parents: np.ndarray, order: np.ndarray, reverse: bool
) -> tuple:
    """:func:`carry_frame` over time (backwards in time with ``reverse``): the
    pseudo-measurements ``(T, B, J, 3)`` and their radii ``(T, B, J)``, NaN where none."""
    T, B, J = ys.shape[0], ys.shape[1], ys.shape[2]
    pseudo = np.full((T, B, J, 3), np.nan)
    radius = np.full((T, B, J), np.nan)
    off = np.full((B, J, 3), np.nan)
    anchor = np.empty((J, 3))
    for i in range(T):
        t = T - 1 - i if reverse else i
        for b in range(B):
            carry_frame(ys[t, b], acc[t, b], parents, order, off[b], anchor, pseudo[t, b],
                        radius[t, b])  # fmt: skip
    return pseudo, radius


@_jit
def carried_count(tau: float, dt: float) -> float:
    """How many carried samples count as one offline: those within the motion's
    correlation time ``tau`` (``tau / dt``, at least 1; 1 when ``tau`` is infinite). A
    carried sample is the parent plus the joint's last good offset, so consecutive ones
    share one error, the limb's rotation about its parent since, which decorrelates over
    ``tau``; their variance is multiplied by this count, so that a run of them does not
    outvote the real samples at both ends of the bridge. (Online there is nothing ahead
    to bridge to: the carried samples keep their single weight, docs/robust.md.)"""
    if not math.isfinite(tau) or not dt > 0.0:
        return 1.0
    return max(1.0, tau / dt)


@_jit
def carry_both(
    ys: np.ndarray,  # (T, B, J, 3)
    acc: np.ndarray,  # (T, B, J)
    parents: np.ndarray,
    order: np.ndarray,
    sd: np.ndarray,  # (B, J) measurement standard deviation
    steps: np.ndarray,  # (T,) time step before each frame
    tau: float,
    yk: np.ndarray,  # out (T, B, J, 3) the smoother's samples
    rvar: np.ndarray,  # (T, B, J) their variances: the carried ones' written in
) -> None:
    """Offline carrying: the smoother's samples ``yk`` are the accepted measurements,
    the rejected ones carried (forwards in time, and backwards for the samples with no
    earlier good offset), NaN elsewhere. A carried sample's variance is
    ``sd² max(1, (radius / sd)²)`` (its standard deviation is the bone's length, the
    joint may have rotated about its parent; at least the measurement's own) times
    :func:`carried_count`."""
    T, B, J = ys.shape[0], ys.shape[1], ys.shape[2]
    radius = np.full((T, B, J), np.nan)
    off = np.full((B, J, 3), np.nan)
    anchor = np.empty((J, 3))
    pseudo = np.empty((J, 3))
    rad = np.empty(J)
    for back in (False, True):
        off.fill(np.nan)
        for i in range(T):
            t = T - 1 - i if back else i
            for b in range(B):
                if not back:
                    for j in range(J):
                        a = acc[t, b, j]
                        for c in range(3):
                            yk[t, b, j, c] = ys[t, b, j, c] if a else math.nan
                carry_frame(ys[t, b], acc[t, b], parents, order, off[b], anchor, pseudo, rad)
                for j in range(J):
                    if math.isfinite(rad[j]) and not (back and math.isfinite(radius[t, b, j])):
                        radius[t, b, j] = rad[j]
                        yk[t, b, j, 0] = pseudo[j, 0]
                        yk[t, b, j, 1] = pseudo[j, 1]
                        yk[t, b, j, 2] = pseudo[j, 2]
    for t in range(T):
        n = carried_count(tau, steps[t])
        for b in range(B):
            for j in range(J):
                if math.isfinite(radius[t, b, j]):
                    s = sd[b, j]
                    v = radius[t, b, j] / s
                    v = v * v
                    rvar[t, b, j] = n * (s * s) * (1.0 if v <= 1.0 else v)


# ------------------------------------------------------------------------------ OU filter
@_jit
def _predict_P(
    p00: float, p01: float, p10: float, p11: float, c: np.ndarray, k: int, q: float
) -> tuple:
    """A P Aᵀ + q Q with A, Q from the coefficients ``c[k]`` (:func:`ou_coeffs`)."""
    a, r = c[k, 0], c[k, 1]
    m00 = p00 + a * p10
    m01 = p01 + a * p11
    m10 = r * p10
    m11 = r * p11
    return (m00 + m01 * a + q * c[k, 2], m01 * r + q * c[k, 3], m10 + m11 * a + q * c[k, 3],
            m11 * r + q * c[k, 4])  # fmt: skip


@_jit
def _update_P(p00: float, p01: float, p10: float, p11: float, r: float) -> tuple:
    """Kalman gain (k0, k1) for H = [1, 0] and variance r, and the updated P
    (symmetrised): ``(k0, k1, p00, p01, p10, p11)``."""
    S = p00 + r
    k0 = p00 / S
    k1 = p10 / S
    n00 = p00 - k0 * p00
    n01 = p01 - k0 * p01
    n10 = p10 - k1 * p00
    n11 = p11 - k1 * p01
    s = 0.5 * (n01 + n10)
    return k0, k1, n00, s, s, n11


# ------------------------------------------------------------------------------ online
@_jit
def shared_frame(
    y: np.ndarray,  # (J, 3) this frame of the body
    final: np.ndarray,  # (J,) accepted
    radius: np.ndarray,  # (J,) carried joints' offset lengths (carry_frame), NaN elsewhere
    parents: np.ndarray,
    order: np.ndarray,
    tidx: int,  # this frame's index in the stream
    min_pairs: int,
    n_dims: int,  # coordinates (2: the third axis is zeros)
    sf: np.ndarray,  # state (J, N_SF): S_OFF_FRAME, S_O_N, S_O_SUM .. + 2, S_O_SS
    o_ring: np.ndarray,  # state (SF_RING, J, 3) the offsets of the last frames, NaN unknown
    s_acc: np.ndarray,  # state (2, n_lags, J): sums of the squared differences, pairs
    sig2: np.ndarray,  # out (J,) per-axis variance of each carried sample's error, else 0
) -> None:
    """Online shared errors of the carried samples: the causal form of
    :func:`tobitkf.smoothing._shared_kernels.carried_sd`. A carried sample ``Δ`` frames
    from the offset it carries has per-axis variance ``S(Δ) / n_dims`` (plus its parent's
    when that is carried too), ``S`` the structure function of the joint's offset from
    its parent over the frames so far, read at the smallest of :data:`SF_LAGS` at least
    ``Δ``; a lag with fewer than ``min_pairs`` pairs, or beyond the last, takes the
    stationary limit ``2 Var(o)`` of the offsets so far. Then this frame's offsets join
    the statistics. (The ring is slot-major, the sums lag-major: each lag's pairs of all
    joints are one contiguous pass.)"""
    J = parents.shape[0]
    R = o_ring.shape[0]
    n_lags = SF_LAGS.shape[0]
    slot = tidx % R
    sums, cnts = s_acc[0], s_acc[1]
    for k in range(J):  # the carried samples, from the root outwards (a parent first)
        j = order[k]
        p = parents[j]
        sig2[j] = 0.0
        if p < 0 or not math.isfinite(radius[j]):  # radius: carried joints only
            continue
        lag = tidx - sf[j, S_OFF_FRAME]
        n = sf[j, S_O_N]  # 2 Var(o): the sample variance summed over the axes
        c0, c1, c2 = sf[j, S_O_SUM], sf[j, S_O_SUM + 1], sf[j, S_O_SUM + 2]
        ss = sf[j, S_O_SS] - (c0 * c0 + c1 * c1 + c2 * c2) / max(n, 1.0)
        v = 2.0 * max(ss, 0.0) / max(n - 1.0, 1.0)
        for m in range(n_lags):
            if SF_LAGS[m] >= lag:
                if cnts[m, j] >= min_pairs:
                    v = sums[m, j] / cnts[m, j]
                break
        sig2[j] = v / n_dims + sig2[p]
    ring = o_ring[slot]  # this frame's offsets (the slot of tidx - R)
    for j in range(J):
        p = parents[j]
        ok = (p >= 0 and final[j] and final[p] and _finite3(y[j, 0], y[j, 1], y[j, 2])
              and _finite3(y[p, 0], y[p, 1], y[p, 2]))  # fmt: skip
        if not ok:
            ring[j, 0] = ring[j, 1] = ring[j, 2] = math.nan
            continue
        o0, o1, o2 = y[j, 0] - y[p, 0], y[j, 1] - y[p, 1], y[j, 2] - y[p, 2]
        ring[j, 0], ring[j, 1], ring[j, 2] = o0, o1, o2
        sf[j, S_OFF_FRAME] = tidx
        sf[j, S_O_N] += 1.0  # the running sums (offsets are bounded: no cancellation)
        sf[j, S_O_SUM] += o0
        sf[j, S_O_SUM + 1] += o1
        sf[j, S_O_SUM + 2] += o2
        sf[j, S_O_SS] += o0 * o0 + o1 * o1 + o2 * o2
    for m in range(n_lags):  # the pairs this frame closes, a lag at a time
        lg = SF_LAGS[m]
        if lg > tidx:
            break
        s2 = slot - lg  # (tidx - lg) % R without a division: lg < R
        if s2 < 0:
            s2 += R
        past = o_ring[s2]
        for j in range(J):
            d0 = ring[j, 0] - past[j, 0]  # NaN unless both known
            if d0 == d0:
                d1, d2 = ring[j, 1] - past[j, 1], ring[j, 2] - past[j, 2]
                sums[m, j] += d0 * d0 + d1 * d1 + d2 * d2
                cnts[m, j] += 1.0


@_jit
def guess_frame(
    y: np.ndarray,  # (J, 3) this frame of the body (guesses at their bones' lengths)
    yprev: np.ndarray,  # (J, 3) the previous frame's
    has_prev: bool,
    final: np.ndarray,  # (J,) accepted
    inferred: np.ndarray,  # (J,) INFERRED samples
    min_changes: int,
    n_dims: int,
    sf: np.ndarray,  # state (J, N_SF): S_TRK_SUM, S_TRK_N
    sb: np.ndarray,  # state (J, N_SB): B_PREV_FINAL, B_PREV_INF, B_HAS_GUESS (read
    # before the filter writes this frame's)
    g_stat: np.ndarray,  # state (2,): the body's sum of squared steps at a change, count
) -> float:
    """Online shared error of the guesses: the causal form of
    :func:`tobitkf.smoothing.robust_shared.guess_error_variance`. This frame's steps
    whose two samples were accepted join the body's statistics (at a change between
    tracked and inferred, or between two tracked samples); returns the per-axis standard
    deviation of a guess's error from the frames so far, ``sqrt((mean |step|² at a
    change − mean |step|² between tracked samples of the joints with guesses) /
    n_dims)``, 0 before ``min_changes`` changes."""
    J = y.shape[0]
    for j in range(J):
        ok = final[j] and _finite3(y[j, 0], y[j, 1], y[j, 2])
        if ok and inferred[j]:
            sb[j, B_HAS_GUESS] = True
        if not (ok and has_prev and sb[j, B_PREV_FINAL]):
            continue
        if not _finite3(yprev[j, 0], yprev[j, 1], yprev[j, 2]):
            continue
        d0, d1, d2 = y[j, 0] - yprev[j, 0], y[j, 1] - yprev[j, 1], y[j, 2] - yprev[j, 2]
        d = d0 * d0 + d1 * d1 + d2 * d2
        if inferred[j] != sb[j, B_PREV_INF]:
            g_stat[0] += d
            g_stat[1] += 1.0
        elif not inferred[j]:
            sf[j, S_TRK_SUM] += d
            sf[j, S_TRK_N] += 1.0
    if g_stat[1] < min_changes:
        return 0.0
    st = 0.0
    nt = 0.0
    for j in range(J):
        if sb[j, B_HAS_GUESS]:
            st += sf[j, S_TRK_SUM]
            nt += sf[j, S_TRK_N]
    if nt == 0.0:
        return 0.0
    return math.sqrt(max(g_stat[0] / g_stat[1] - st / nt, 0.0) / n_dims)


@_jit
def online_frames(
    ys: np.ndarray,  # (n, B, J, 3) the next n frames, NaN = missing
    missing_n: np.ndarray,  # (n, B, J)
    rinf_n: np.ndarray,  # (n, B, J) variance multiplier of INFERRED samples (else 1)
    project_n: np.ndarray,  # (n, B, J) the guesses put back at their bone's length
    inferred_n: np.ndarray,  # (n, B, J) the INFERRED samples
    times: np.ndarray,  # (n,) time of each frame
    steps: np.ndarray,  # (n,) time step of the filter before each frame
    parents: np.ndarray,
    order: np.ndarray,
    pj: np.ndarray,
    pf: np.ndarray,
    pi: np.ndarray,
    st: tuple,  # new_state(B, J, lookback), carried from call to call
    scratch: np.ndarray,  # work (4, J, 3)
    scratch1: np.ndarray,  # work (4, J)
    acc: np.ndarray,  # work (3, B, J)
    out_n: np.ndarray,  # out (n, B, J, 3)
    rejected_n: np.ndarray,  # out (n, B, J)
    var_n: np.ndarray,  # out (n, B, J): filtered position variance (NaN before the start)
    b0: int,  # the outputs' body b0 + b is body b (a chunk of the outputs' bodies)
) -> None:
    """``robust_online``, frame by frame: gate, confirmation, chain, carrying, causal OU
    filter with roll-back at rejection onsets. Everything it remembers is in ``st``: the
    batch runner passes a whole recording, the live stepper one frame per call."""
    (last, yprev, off, sf, sb, h_val, h_mult, h_cnt, x, P, xs_h, Ps_h, ok_h, coef_h,
     clock, o_ring, s_acc, g_stat) = st  # fmt: skip
    B, J = ys.shape[1], ys.shape[2]
    for f in range(ys.shape[0]):
        y, missing, rinf = ys[f], missing_n[f], rinf_n[f]
        tt, dt = times[f], steps[f]
        out, rejected, var = out_n[f], rejected_n[f], var_n[f]
        tidx = int(clock[0])
        has_prev = tidx > 0
        dt_prev = tt - clock[1] if has_prev else math.inf
        lookback = pi[I_LOOKBACK]
        K = lookback + 1
        slot = tidx % K
        q_c = coef_h[slot]
        ou_coeffs(dt, pf[P_TAU], q_c)
        min_run = pf[P_MIN_RUN]
        use_bones = pi[I_BONES] != 0
        carry = pi[I_CARRY] != 0
        shared = carry and pi[I_SHARED] != 0 and o_ring.shape[1] > 0
        sig2 = scratch1[3]
        anchor = scratch[0]
        pseudo = scratch[1]
        radius = scratch1[0]
        no_lengths = scratch1[1]  # the online gate learns its bone lengths (unused)
        yb = scratch[2]  # this frame of the body, inferred joints at their bone's length
        for b in range(B):
            gate = acc[0, b]
            final = acc[1, b]
            radius.fill(np.nan)
            lengths = scratch1[2]
            for j in range(J):
                lengths[j] = sf[b, j, S_L_CUR]  # learnt so far (NaN before)
            project_frame(y[b], project_n[f, b], parents, order, lengths, yb, scratch[3])
            gate_frame(yb, yprev[b], inferred_n[f, b], has_prev, tt, dt_prev, tidx, parents,
                       order, pj, pf, no_lengths, use_bones, True, pi[I_NDIMS] == 3,
                       pf[P_MAX_REJECT], last[b], sf[b], sb[b], h_val[b], h_mult[b],
                       h_cnt[b], gate)  # fmt: skip
            if min_run > 0:
                confirm_frame(gate, missing[b], tt, min_run, sf[b], final)
                if has_prev:
                    prev_final = acc[2, b]  # contiguous, no allocation: one chain_frame type
                    for j in range(J):
                        prev_final[j] = sb[b, j, B_PREV_FINAL]
                    chain_frame(final, prev_final, yb, yprev[b], abs(dt_prev), parents, order,
                                pj, pf[P_MARGIN])  # fmt: skip
            else:
                for j in range(J):
                    final[j] = gate[j]
            if carry:
                carry_frame(yb, final, parents, order, off[b], anchor, pseudo, radius)
            if shared:
                shared_frame(yb, final, radius, parents, order, tidx, pi[I_MIN_PAIRS],
                             pi[I_NDIMS], sf[b], o_ring[b], s_acc[b], sig2)  # fmt: skip
            guess_sd = 0.0
            if pi[I_SHARED] != 0:
                guess_sd = guess_frame(yb, yprev[b], has_prev, final, inferred_n[f, b],
                                       pi[I_MIN_CHANGES], pi[I_NDIMS], sf[b], sb[b],
                                       g_stat[b])  # fmt: skip
            # the causal OU filter, joint by joint (x[b, j, axis], P[b, j] shared by the axes)
            for j in range(J):
                a = final[j]
                rejected[b0 + b, j] = not (a or missing[b, j])
                carried = carry and not a and math.isfinite(radius[j])
                started = sb[b, j, B_STARTED]
                q = pj[j, J_Q]
                r = pj[j, J_R] * rinf[b, j]
                if carried:
                    r = pj[j, J_R] * max(1.0, (radius[j] / pj[j, J_SD]) ** 2)
                p00, p01, p10, p11 = P[b, j, 0, 0], P[b, j, 0, 1], P[b, j, 1, 0], P[b, j, 1, 1]
                # a rejection starts: drop the last `lookback` accepted frames from the state
                if (
                    lookback > 0
                    and tidx > lookback
                    and started
                    and sb[b, j, B_PREV_OK]
                    and not a
                    and not missing[b, j]
                ):
                    s0 = (tidx - lookback - 1) % K
                    if ok_h[s0, b, j]:
                        for i in range(N_X):  # the axes and the indicator filters
                            x[b, j, i, 0] = xs_h[s0, b, j, i, 0]
                            x[b, j, i, 1] = xs_h[s0, b, j, i, 1]
                        p00, p01, p10, p11 = Ps_h[s0, b, j, 0], Ps_h[s0, b, j, 1], \
                            Ps_h[s0, b, j, 2], Ps_h[s0, b, j, 3]  # fmt: skip
                        for kk in range(tidx - lookback, tidx):
                            c = kk % K
                            for i in range(N_X):
                                x[b, j, i, 0], x[b, j, i, 1] = (
                                    x[b, j, i, 0] + x[b, j, i, 1] * coef_h[c, 0],
                                    x[b, j, i, 1] * coef_h[c, 1],
                                )
                            p00, p01, p10, p11 = _predict_P(p00, p01, p10, p11, coef_h, c, q)
                if has_prev and started:
                    for i in range(N_X):
                        x[b, j, i, 0], x[b, j, i, 1] = (
                            x[b, j, i, 0] + x[b, j, i, 1] * coef_h[slot, 0],
                            x[b, j, i, 1] * coef_h[slot, 1],
                        )
                    p00, p01, p10, p11 = _predict_P(p00, p01, p10, p11, coef_h, slot, q)
                if a and not started:  # the filter starts at the sample itself
                    for i in range(3):
                        x[b, j, i, 0], x[b, j, i, 1] = yb[j, i], 0.0
                    p00, p01, p10, p11 = r, 0.0, 0.0, pj[j, J_V0]
                    sb[b, j, B_STARTED] = True
                elif started and (a or carried):
                    k0, k1, p00, p01, p10, p11 = _update_P(p00, p01, p10, p11, r)
                    for i in range(3):
                        e = (yb[j, i] if a else pseudo[j, i]) - x[b, j, i, 0]
                        x[b, j, i, 0] += k0 * e
                        x[b, j, i, 1] += k1 * e
                    # the indicator filters: the same gains on the shared errors' sd (the
                    # carried samples', the guesses'; 0 at other samples) give the
                    # estimate's share of each
                    e = (math.sqrt(sig2[j]) if carried and shared else 0.0) - x[b, j, X_CARRIED, 0]
                    x[b, j, X_CARRIED, 0] += k0 * e
                    x[b, j, X_CARRIED, 1] += k1 * e
                    e = (guess_sd if a and inferred_n[f, b, j] else 0.0) - x[b, j, X_GUESS, 0]
                    x[b, j, X_GUESS, 0] += k0 * e
                    x[b, j, X_GUESS, 1] += k1 * e
                P[b, j, 0, 0], P[b, j, 0, 1], P[b, j, 1, 0], P[b, j, 1, 1] = p00, p01, p10, p11
                for i in range(N_X):
                    xs_h[slot, b, j, i, 0], xs_h[slot, b, j, i, 1] = x[b, j, i, 0], x[b, j, i, 1]
                Ps_h[slot, b, j, 0], Ps_h[slot, b, j, 1] = p00, p01
                Ps_h[slot, b, j, 2], Ps_h[slot, b, j, 3] = p10, p11
                ok_h[slot, b, j] = a
                sb[b, j, B_PREV_OK] = a
                sb[b, j, B_PREV_FINAL] = a
                sb[b, j, B_PREV_INF] = inferred_n[f, b, j]
                started = sb[b, j, B_STARTED]
                var[b0 + b, j] = (p00 + x[b, j, X_CARRIED, 0] ** 2 + x[b, j, X_GUESS, 0] ** 2
                                  if started else np.nan)  # fmt: skip
                for i in range(3):
                    # nothing accepted yet: the measurement as it is (NaN when missing)
                    out[b0 + b, j, i] = x[b, j, i, 0] if started else yb[j, i]
            _copy2(yprev[b], yb)
        clock[0] = tidx + 1
        clock[1] = tt

"""Is the posterior sd honest? The share of samples in the 95 % ball of a method's own sd.

The expected numbers come from the Gaussian model independently of the code under test:
errors drawn with a known per-axis sd land in the 95 % ball 95 % of the time, and errors
twice as large in it with probability P(chi2_3 <= 7.8147 / 4) (scipy's chi-square CDF).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.stats import chi2

from tobitkf.evaluation.evaluate import evaluate_methods, pool_scores
from tobitkf.evaluation.markdown import evaluation_markdown
from tobitkf.evaluation.metrics import in_sd_ball, sample_share
from tobitkf.evaluation.synthetic import generate_motion

CHI2_3_95 = 7.8147  # chi-square quantile, 3 degrees of freedom, 0.95 (tables)


def _draws(n_frames: int, n_joints: int, dim: int, scale: float, seed: int):
    """Truth, estimate = truth + scale * sd * N(0, I) and the (T, J) sd that was used."""
    rng = np.random.default_rng(seed)
    truth = rng.normal(size=(n_frames, n_joints, dim))
    sd = rng.uniform(0.005, 0.05, size=(n_frames, n_joints))  # a different sd per sample
    est = truth + scale * sd[..., None] * rng.normal(size=truth.shape)
    return est, truth, sd


def _within_4_se(share: float, p: float, n: int) -> None:
    se = math.sqrt(p * (1 - p) / n)
    assert abs(share - p) < 4 * se, (share, p, se)


@pytest.mark.parametrize("dim", [3, 2])
def test_honest_gaussian_errors_cover_95_percent(dim) -> None:
    est, truth, sd = _draws(20_000, 10, dim, 1.0, seed=dim)
    share, n = sample_share(in_sd_ball(est, truth, sd))
    assert n == 200_000
    _within_4_se(share, 0.95, n)


def test_errors_twice_the_sd_cover_the_chi_square_probability() -> None:
    est, truth, sd = _draws(20_000, 10, 3, 2.0, seed=7)
    share, n = sample_share(in_sd_ball(est, truth, sd))
    p = chi2.cdf(CHI2_3_95 / 4, 3)  # |e|² / (2 sd)² ~ chi2_3
    assert 0.4 < p < 0.45
    _within_4_se(share, p, n)


def test_missing_samples_and_sds_are_not_counted() -> None:
    est, truth, sd = _draws(4, 2, 3, 1.0, seed=0)
    est[0, 0] = np.nan
    sd[1, 1] = np.nan
    hits = in_sd_ball(est, truth, sd)
    assert np.isnan(hits[0, 0]) and np.isnan(hits[1, 1])
    assert sample_share(hits)[1] == 6


# ------------------------------------------------------------------- through the tables
@pytest.fixture(scope="module")
def track():
    return generate_motion("mixed", duration=4.0, seed=5)


def _claimed(offset_m: float, sd_m: float, bad_from: int | None = None):
    """A method whose estimate is off by ``offset_m`` on x (from frame ``bad_from`` on,
    else exact) and which claims the sd ``sd_m`` everywhere."""

    def run(s):
        p = s.positions.copy()
        p[bad_from or 0 :, :, 0] += offset_m if bad_from is not None else 0.0
        return s.replace(positions=p, std=np.full(p.shape[:2], sd_m))

    return run


def test_pooling_weighs_recordings_by_their_samples(track) -> None:
    short = track.replace(
        positions=track.positions[:90], tracking_state=None, timestamps=track.timestamps[:90]
    )
    # long recording: exact, every sample inside; short one: exact for 30 frames, then 10 cm
    # off with a claimed sd of 1 cm (|e|² = 1e-2 > 7.8 · 1e-4: outside)
    a = evaluate_methods(track, track.positions, ["raw", ("claimed", _claimed(0.1, 0.01, None))])
    b = evaluate_methods(short, short.positions, ["raw", ("claimed", _claimed(0.1, 0.01, 30))])
    assert a.score("claimed").in_sd_ball == 1.0
    assert b.score("claimed").in_sd_ball == pytest.approx(30 / 90)
    J = track.n_joints
    n_a, n_b = track.n_frames * J, 90 * J
    expected = 100 * (n_a + 30 * J) / (n_a + n_b)  # not the mean of 100 % and 33 %
    pooled = {r["method"]: r for r in pool_scores([a, b])}
    assert pooled["claimed"]["in_95_ball_pct"] == pytest.approx(expected)
    assert pooled["claimed"]["fine_in_95_ball_pct"] == pytest.approx(expected)
    assert pooled["raw"]["in_95_ball_pct"] is None


def test_json_gives_the_share_in_percent_per_recording_as_pooled(track, tmp_path) -> None:
    """``evaluate --json`` gave each recording's share as a fraction (``in_sd_ball``) and
    the pooled one in percent (``in_95_ball_pct``): one unit, named, in both."""
    short = track.replace(
        positions=track.positions[:90], tracking_state=None, timestamps=track.timestamps[:90]
    )
    # exact for 30 of 90 frames, then 10 cm off with a claimed sd of 1 cm: outside
    tab = evaluate_methods(short, short.positions, ["raw", ("claimed", _claimed(0.1, 0.01, 30))])
    scores = {s["method"]: s for s in json.loads(json.dumps(tab.to_dict()))["scores"]}
    assert scores["claimed"]["in_95_ball_pct"] == pytest.approx(100 * 30 / 90)
    by_class = scores["claimed"]["in_95_ball_pct_by_class"]
    assert by_class["fine"] == pytest.approx(100 * 30 / 90)  # raw is exact: all fine
    assert by_class["sustained"] is None  # no sample of that class
    assert scores["raw"]["in_95_ball_pct"] is None  # no sd
    assert not [k for s in scores.values() for k in s if k.startswith("in_sd_ball")]
    # the CLI: one recording twice, so the pooled share is each recording's, in one unit
    from click.testing import CliRunner

    from tobitkf.app.commands import app
    from tobitkf.io import save

    save([short], tmp_path / "track.csv", format="csv")
    save([short], tmp_path / "truth.csv", format="csv")
    args = ["evaluate", *[str(tmp_path / "track.csv")] * 2, "--methods", "kf", "--json"]
    res = CliRunner().invoke(app, [*args, *["--truth", str(tmp_path / "truth.csv")] * 2])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    (pooled,) = out.pop("pooled")
    (table,) = out.values()  # both recordings have the same path
    (kf,) = table["scores"]
    assert 0 < kf["in_95_ball_pct"] <= 100  # percent (the fraction was at most 1)
    assert kf["in_95_ball_pct"] == pytest.approx(pooled["in_95_ball_pct"])


def test_a_method_without_an_sd_has_no_coverage_and_shows_a_dash(track) -> None:
    tab = evaluate_methods(track, track.positions, ["raw", ("claimed", _claimed(0.0, 0.01))])
    assert tab.score("raw").in_sd_ball is None
    assert tab.score("raw").row()["in_95_ball_pct"] is None
    assert tab.score("claimed").row()["in_95_ball_pct"] == 100.0
    md = evaluation_markdown([tab], ["rec"])
    header = next(line for line in md.splitlines() if line.startswith("| method | RMSE"))
    assert header.rstrip(" |").endswith("in 95% ball")
    raw_row = next(line for line in md.splitlines() if line.startswith("| raw |"))
    assert raw_row.rstrip(" |").endswith("–")
    assert "| claimed | 100.0 | 100.0 |" in md  # the per-class table: methods with an sd
    assert "95% ball" in tab.to_text()


def test_benchmark_scores_the_coverage_per_label() -> None:
    from tobitkf.evaluation.benchmark import run_benchmark, seed_ball, seed_spread
    from tobitkf.evaluation.markdown import benchmark_markdown

    tab = run_benchmark(seed=1, methods=["raw", "kf"], duration=3.0)
    assert tab.row("raw").in_sd_ball is None
    kf = tab.row("kf")
    assert 0.0 < kf.in_sd_ball <= 1.0 and kf.sd_counts["all"] > 0
    assert set(kf.in_sd_ball_by_label) == {"clean", "spike", "sustained", "inferred"}
    ball = seed_ball([tab, tab])
    assert ball[0]["in_95_ball_pct"] is None
    assert ball[1]["in_95_ball_pct"] == pytest.approx(100 * kf.in_sd_ball)
    md = benchmark_markdown(seed_spread([tab]), [1], ball)
    assert "| method | in 95% ball | clean | spike | sustained | inferred |" in md
    assert "| raw |" not in md.split("in 95% ball")[1]  # no sd: not in the coverage table


# ------------------------------------------------------------------------------ report
def test_the_traces_draw_a_band_of_2_sd_behind_the_curve() -> None:
    pytest.importorskip("matplotlib")
    from tobitkf.app import plots

    t = np.arange(40) / 30
    curve = np.stack([np.sin(t), np.cos(t), t], axis=1)
    sd = np.full(40, 0.05)
    fig = plots.plot_joint_traces(t, {"raw": curve, "robust": curve}, bands={"robust": sd})
    labels = [x.get_text() for x in fig.legends[0].get_texts()]
    assert labels == ["raw", "robust", "robust ± 2 sd"]
    ax = fig.axes[0]
    band = ax.collections[0]
    lines = {ln.get_label(): ln for ln in ax.get_lines()}
    assert band.get_zorder() < lines["robust"].get_zorder()  # behind the lines
    lo, hi = band.get_paths()[0].vertices[:, 1].min(), band.get_paths()[0].vertices[:, 1].max()
    assert lo == pytest.approx(curve[:, 0].min() - 0.1) and hi == pytest.approx(
        curve[:, 0].max() + 0.1
    )
    plots.figure_to_png(fig)


@pytest.mark.parametrize("methods", [["raw", "robust"], ["raw", "kf"]])
def test_the_report_draws_and_explains_the_band_when_robust_is_traced(
    track, tmp_path, monkeypatch, methods
) -> None:
    pytest.importorskip("matplotlib")
    from tobitkf.app import plots
    from tobitkf.app.report import track_report

    drawn = []  # the bands every trace figure was drawn with
    original = plots.plot_joint_traces

    def spy(*args, **kwargs):
        drawn.append(kwargs.get("bands") or {})
        return original(*args, **kwargs)

    monkeypatch.setattr(plots, "plot_joint_traces", spy)
    path, _ = track_report(
        track, tmp_path / "r.html", truth=track.positions, methods=methods, gif=False
    )
    page = path.read_text(encoding="utf-8")
    assert ("robust ± 2 sd" in page) == ("robust" in methods)
    assert drawn and all((list(b) == ["robust"]) == ("robust" in methods) for b in drawn)
    if "robust" in methods:
        sd = drawn[0]["robust"]
        assert sd.shape == (track.n_frames,) and np.all(sd > 0)
    assert "in 95% ball (%)" in page

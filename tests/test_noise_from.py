"""A noise fit read back from a file (``tk.read_noise_fit``, ``tobitkf smooth
--noise-from``): every robust output records its fit in its provenance, and the fit read
from the output file (CSV with its sidecar, the sidecar itself, NPZ, a JSON of the fit)
smooths another recording exactly as the fit taken in Python from the first one's
diagnostics does; a file that holds no fit is refused with the reason."""

from __future__ import annotations

import json

import numpy as np
import pytest

click = pytest.importorskip("click")
from click.testing import CliRunner  # noqa: E402

import tobitkf as tk  # noqa: E402
from tobitkf.app.commands import app  # noqa: E402
from tobitkf.core.jsonable import dumps  # noqa: E402

REGIONS = ("hands", "arms", "torso", "legs")


def _recording(seed: int, seconds: float) -> tk.SkeletonSequence:
    bad = tk.corrupt(tk.generate_motion("mixed", duration=seconds, seed=seed), seed=seed)
    return bad.sequence


def _cli(*args: str):
    return CliRunner().invoke(app, list(args))


@pytest.fixture(scope="module")
def long_run(tmp_path_factory):
    """A long recording smoothed by ``tobitkf smooth`` to CSV and to NPZ, and its fit as
    Python gives it (``diagnostics["noise_fit"]`` of ``tk.smooth``)."""
    d = tmp_path_factory.mktemp("long")
    seq = _recording(3, 8.0)
    tk.save([seq], d / "long.csv", format="csv")
    for fmt in ("csv", "npz"):
        res = _cli("smooth", str(d / "long.csv"), "-o", str(d / fmt), "-f", fmt)
        assert res.exit_code == 0, res.output
    fit = tk.smooth(seq).metadata["diagnostics"]["noise_fit"]
    assert all(fit[g]["fitted"] for g in REGIONS)
    return d, fit


def test_the_provenance_records_the_fit_of_the_diagnostics():
    out = tk.smooth(_recording(4, 4.0))
    recorded = out.metadata["provenance"]["params"]["noise_fit"]
    assert recorded == out.metadata["diagnostics"]["noise_fit"]
    fixed = tk.smooth(_recording(4, 4.0), noise="fixed").metadata["provenance"]["params"]
    assert "noise_fit" not in fixed


def test_every_file_form_gives_the_fit(long_run, tmp_path):
    d, fit = long_run
    as_json = tmp_path / "fit.json"
    as_json.write_text(dumps(fit))
    wrapped = tmp_path / "wrapped.json"
    wrapped.write_text(dumps({"noise_fit": fit, "note": "from the long session"}))
    forms = [
        d / "csv" / "long.robust.csv",
        d / "csv" / "long.robust.json",  # the sidecar itself
        d / "npz" / "long.robust.npz",
        as_json,
        wrapped,
    ]
    short = _recording(5, 3.0)
    want = tk.smooth(short, noise=fit)
    for path in forms:
        got = tk.read_noise_fit(path)
        assert set(got) == set(REGIONS), path
        for g in REGIONS:
            for key in ("speed_sd", "noise_sd", "error_sd", "error_tau"):
                assert got[g][key] == fit[g][key], (path, g, key)
        out = tk.smooth(short, noise=got)
        np.testing.assert_array_equal(out.positions, want.positions)
        np.testing.assert_array_equal(out.std, want.std)


def test_the_cli_smooths_with_the_fit_read(long_run, tmp_path):
    d, fit = long_run
    short = _recording(6, 3.0)
    tk.save([short], tmp_path / "short.csv", format="csv")
    side = d / "csv" / "long.robust.json"
    res = _cli("smooth", str(tmp_path / "short.csv"), "-o", str(tmp_path / "o"), "-f", "npz",
               "--noise-from", str(side))  # fmt: skip
    assert res.exit_code == 0, res.output
    got = tk.load(tmp_path / "o" / "short.robust.npz")[0]
    # the recording as the CLI read it, smoothed in Python with the long one's own fit
    want = tk.smooth(tk.load(tmp_path / "short.csv")[0], noise=fit)
    np.testing.assert_array_equal(got.positions, want.positions)
    np.testing.assert_array_equal(got.std, want.std)
    own = tk.smooth(tk.load(tmp_path / "short.csv")[0])
    assert not np.array_equal(got.positions, own.positions)  # not its own fit
    report = got.metadata["provenance"]["params"]["noise_fit"]
    assert all(report[g]["given"] for g in REGIONS)


def test_files_without_a_fit_are_refused_with_the_reason(tmp_path):
    seq = _recording(7, 3.0)
    raw = tmp_path / "raw.csv"
    tk.save([seq], raw, format="csv")
    with pytest.raises(ValueError, match="no provenance"):
        tk.read_noise_fit(raw)
    fixed = tmp_path / "fixed.npz"
    tk.save([tk.smooth(seq, noise="fixed")], fixed, format="npz")
    with pytest.raises(ValueError, match="noise='fixed'"):
        tk.read_noise_fit(fixed)
    kf = tmp_path / "kf.npz"
    tk.save([tk.smooth(seq, "kf")], kf, format="npz")
    with pytest.raises(ValueError, match="'kf', which fits no noise"):
        tk.read_noise_fit(kf)
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"hands": 1.0}))
    with pytest.raises(ValueError, match="neither a noise fit"):
        tk.read_noise_fit(other)
    with pytest.raises(FileNotFoundError):
        tk.read_noise_fit(tmp_path / "absent.csv")


def test_bodies_with_different_fits_need_a_choice(tmp_path):
    a, b = _recording(8, 4.0), _recording(9, 4.0)
    outs = tk.smooth([a, b])
    path = tmp_path / "two.npz"
    tk.save(outs, path, format="npz")
    with pytest.raises(ValueError, match="different noise fits"):
        tk.read_noise_fit(path)
    for k in (0, 1):
        got = tk.read_noise_fit(path, body=k)
        want = outs[k].metadata["diagnostics"]["noise_fit"]
        assert all(got[g]["speed_sd"] == want[g]["speed_sd"] for g in REGIONS)
    with pytest.raises(ValueError, match="body 2 asked for, the file has 2"):
        tk.read_noise_fit(path, body=2)


def test_the_cli_refuses_what_takes_no_fit(long_run, tmp_path):
    d, _ = long_run
    side = str(d / "csv" / "long.robust.json")
    src = str(d / "long.csv")
    for extra, reason in [
        (["-m", "robust_online"], "robust_online takes no noise fit"),
        (["-m", "kf"], "kf takes no noise fit"),
        (["-p", "noise=fixed"], "give the noise once"),
    ]:
        res = _cli("smooth", src, "-o", str(tmp_path / "o"), *extra, "--noise-from", side)
        assert res.exit_code == 2 and reason in res.output, res.output
    res = _cli("smooth", src, "-o", str(tmp_path / "o"), "--noise-from", src)
    assert res.exit_code == 2 and "no provenance" in res.output
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({g: {"speed_sd": -1.0 if g == "legs" else 0.5, "noise_sd": 0.01,
                                   "error_sd": 0.0, "error_tau": 0.1, "fitted": True}
                               for g in REGIONS}))  # fmt: skip
    res = _cli("smooth", src, "-o", str(tmp_path / "o"), "--noise-from", str(bad))
    assert res.exit_code == 2 and "--noise-from" in res.output
    assert "noise['legs']['speed_sd'] must be a positive" in res.output
    assert not (tmp_path / "o").exists()  # refused before anything was written


def test_a_fit_holds_for_data_in_its_own_units_only():
    """The fit records the units the method saw (metres for any length, pixels, unknown
    units); a recording in other units refuses it, one in millimetres takes a fit made in
    metres and gives the metre result scaled (lengths are converted to metres first)."""
    seq = _recording(10, 4.0)
    fit = tk.smooth(seq).metadata["diagnostics"]["noise_fit"]
    assert {r["units"] for r in fit.values()} == {"m"}
    mm = seq.replace(positions=seq.positions * 1000, units="mm")
    np.testing.assert_allclose(tk.smooth(mm, noise=fit).positions / 1000,
                               tk.smooth(seq, noise=fit).positions, rtol=0, atol=1e-12)  # fmt: skip
    px = seq.replace(positions=seq.positions * 500, units="px")
    unknown = seq.replace(units=None)
    with pytest.raises(ValueError, match="made on a recording in m, and this one is in px"):
        tk.smooth(px, noise=fit)
    with pytest.raises(ValueError, match="in m, and this one is in unknown units"):
        tk.smooth(unknown, noise=fit)
    fit_px = tk.smooth(px).metadata["diagnostics"]["noise_fit"]
    assert {r["units"] for r in fit_px.values()} == {"px"}
    with pytest.raises(ValueError, match="made on a recording in px, and this one is in m"):
        tk.smooth(seq, noise=fit_px)
    # a fit that says nothing of its units is taken as given, in any units
    bare = {g: {k: v for k, v in r.items() if k != "units"} for g, r in fit.items()}
    tk.smooth(px, noise=bare)
    with pytest.raises(ValueError, match=r"\['units'\] must be 'm'"):
        tk.smooth(seq, noise={g: {**r, "units": "mm"} for g, r in fit.items()})


def test_the_cli_refuses_a_fit_of_other_units(long_run, tmp_path):
    d, _ = long_run
    seq = tk.load(d / "long.csv")[0]
    px = tmp_path / "px.csv"
    tk.save([seq.replace(positions=seq.positions * 500, units="px")], px, format="csv")
    res = _cli("smooth", str(px), "-o", str(tmp_path / "o"),
               "--noise-from", str(d / "csv" / "long.robust.json"))  # fmt: skip
    assert res.exit_code == 1 and "made on a recording in m, and this one is in px" in res.output

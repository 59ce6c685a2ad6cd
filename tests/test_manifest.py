"""The run manifest and resume, on the local pool (no Dask needed)."""

from __future__ import annotations

import hashlib
import json

import pytest
from click.testing import CliRunner

import tobitkf as tk
from tobitkf.app.commands import app
from tobitkf.app.manifest import MANIFEST_NAME, Manifest, ManifestBusy, read_entries
from tobitkf.evaluation.ntu_like import write_ntu_like

METHOD = "kf"


@pytest.fixture
def src(tmp_path):
    write_ntu_like(tmp_path / "in", 4, frames=(30, 50))
    return tmp_path / "in"


def _skipped(results) -> list[str]:
    return sorted(r.source for r in results if r.extra.get("skipped"))


def test_a_rerun_passes_over_what_is_done_and_redoes_what_changed(src, tmp_path):
    out = tmp_path / "out"
    first = tk.smooth_files(src, out, METHOD, jobs=2)
    inputs = sorted(r.source for r in first)
    assert all(r.ok for r in first) and _skipped(first) == []
    again = tk.smooth_files(src, out, METHOD)
    assert _skipped(again) == inputs
    assert [r.frames for r in again] == [r.frames for r in first]  # from the manifest
    # an input changed (same size: only its hash tells), an output deleted
    changed = sorted(src.rglob("*.skeleton"))[0]
    text = changed.read_bytes()
    i = text.index(b"\n25\n") + 7  # a digit of the first joint's x coordinate
    assert text[i : i + 1].isdigit()
    changed.write_bytes(text[:i] + (b"5" if text[i : i + 1] != b"5" else b"6") + text[i + 1 :])
    assert len(changed.read_bytes()) == len(text)
    gone = next(r for r in first if r.source != str(changed))
    (out / gone.output).unlink()
    third = tk.smooth_files(src, out, METHOD)
    assert sorted(set(inputs) - set(_skipped(third))) == sorted([str(changed), gone.source])
    entry = read_entries(out / MANIFEST_NAME)[str(changed.resolve())]
    assert entry["sha256"] == hashlib.sha256(changed.read_bytes()).hexdigest()
    # other parameters, --overwrite: everything again
    assert _skipped(tk.smooth_files(src, out, METHOD, params={"q": 0.01})) == []
    assert _skipped(tk.smooth_files(src, out, METHOD, params={"q": 0.01})) == inputs
    assert _skipped(tk.smooth_files(src, out, METHOD, params={"q": 0.01}, overwrite=True)) == []
    assert len((out / MANIFEST_NAME).read_text().splitlines()) == len(inputs)


def test_the_command_says_what_it_passed_over(src, tmp_path):
    out = tmp_path / "out"
    args = ["smooth", str(src), "-o", str(out), "-m", METHOD]
    first = CliRunner().invoke(app, args)
    assert first.exit_code == 0 and first.output.rstrip().endswith("4 smoothed")
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    assert "passed over 4 file(s) done by an earlier run" in " ".join(res.output.split())
    assert res.output.rstrip().endswith("0 smoothed, 4 passed over as done")


def test_failures_name_their_output_by_absolute_path_and_json_lists_every_input(
    src, tmp_path, monkeypatch
):
    """A failed input's entry names where its output would be as the others do (an
    absolute path), and --json on a re-run lists the inputs passed over as done too."""
    (src / "broken.skeleton").write_text("3\n1\n")
    monkeypatch.chdir(tmp_path)
    args = ["smooth", "in", "-o", "out", "-m", METHOD, "--json"]
    first = CliRunner().invoke(app, args)
    assert first.exit_code == 1
    entries = read_entries(tmp_path / "out" / MANIFEST_NAME)
    assert len(entries) == 5
    for e in entries.values():
        assert e["output"].startswith(str(tmp_path / "out") + "/")
    assert [e["status"] for e in entries.values()].count("failed") == 1
    plain = CliRunner().invoke(app, [*args[:-1], "--overwrite"])
    assert plain.output.rstrip().endswith("4 smoothed, 1 failed")
    again = json.loads(CliRunner().invoke(app, args).output)
    assert len(again) == 5
    assert sum(bool(r["extra"].get("skipped")) for r in again) == 4


def test_a_line_cut_short_by_a_kill_is_ignored_and_the_next_starts_clean(tmp_path):
    path = tmp_path / MANIFEST_NAME
    whole = {"input": "/a", "status": "ok"}
    odd = {"input": "/d", "output": ["not", "a", "path"]}  # a line no run wrote
    path.write_text(json.dumps(whole) + "\n" + json.dumps(odd) + "\n" + '{"input": "/b", "stat')
    assert list(read_entries(path)) == ["/a"]
    with Manifest(tmp_path) as m:
        m.record({"input": "/c", "status": "ok"})
        assert set(read_entries(path)) == {"/a", "/c"}  # appended on a line of its own
    assert [json.loads(line)["input"] for line in path.read_text().splitlines()] == ["/a", "/c"]


def test_two_runs_cannot_write_one_manifest(tmp_path):
    with Manifest(tmp_path), pytest.raises(ManifestBusy, match="another tobitkf run"):
        Manifest(tmp_path).__enter__()


def test_without_dask_the_cluster_option_says_how_to_install_it(src, tmp_path, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "distributed", None)  # import fails
    args = ["smooth", str(src), "-o", str(tmp_path / "o"), "--cluster", "local"]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 1
    assert "pip install 'tobitkf[dask]'" in " ".join(res.output.split())
    assert not (tmp_path / "o" / MANIFEST_NAME).exists()  # nothing started
    res = CliRunner().invoke(app, [*args[:4], "--workers", "2"])
    assert res.exit_code == 2 and "--cluster local" in res.output


def test_inputs_and_outputs_named_by_urls(src, tmp_path):
    fsspec = pytest.importorskip("fsspec", reason="fsspec is not installed")
    memory = fsspec.filesystem("memory")
    root = f"memory://tobitkf-test-{tmp_path.name}"
    try:
        for p in sorted(src.rglob("*.skeleton")):
            memory.pipe(f"{root}/in/{p.relative_to(src).as_posix()}", p.read_bytes())
        local = tk.smooth_files(src, tmp_path / "local", METHOD, output_format="csv")
        remote = tk.smooth_files(f"{root}/in", f"{root}/out", METHOD, output_format="csv")
        assert [r.ok for r in remote] == [True] * len(local)
        for r, here in zip(remote, local, strict=True):
            # the same table; the sidecar names the URL as the source
            assert memory.cat(r.output) == open(here.output, "rb").read()
            sidecar = json.loads(memory.cat(r.output[: -len(".csv")] + ".json"))
            assert sidecar["provenance"]["source"]["path"] == r.source
            assert r.source.startswith("memory://") and r.output.startswith("memory://")
        lines = memory.cat(f"{root}/out/{MANIFEST_NAME}").decode().splitlines()
        assert sorted(json.loads(line)["input"] for line in lines) == sorted(
            r.source for r in remote
        )
        memory.rm(remote[0].output[: -len(".csv")] + ".json")  # a side file gone: redone
        again = tk.smooth_files(f"{root}/in", f"{root}/out", METHOD, output_format="csv")
        assert [r.source for r in again if not r.extra.get("skipped")] == [remote[0].source]
    finally:
        if memory.exists(root):
            memory.rm(root, recursive=True)


def test_a_uiprmd_pair_named_by_urls_is_read_together(tmp_path, shared_data):
    """Positions and angles in their Kinect/Positions and Kinect/Angles folders on remote
    storage: one recording (the angles are no input), read as the local pair is."""
    fsspec = pytest.importorskip("fsspec", reason="fsspec is not installed")
    kinect = "ui-prmd/Segmented Movements/Kinect"
    pos = shared_data(f"{kinect}/Positions/m01_s01_e01_positions.txt.gz")
    ang = shared_data(f"{kinect}/Angles/m01_s01_e01_angles.txt.gz")
    memory = fsspec.filesystem("memory")
    root = f"memory://tobitkf-uiprmd-{tmp_path.name}"
    try:
        memory.pipe(f"{root}/in/Positions/{pos.name}", pos.read_bytes())
        memory.pipe(f"{root}/in/Angles/{ang.name}", ang.read_bytes())
        (res,) = tk.smooth_files(f"{root}/in", f"{root}/out", METHOD, output_format="csv")
        assert res.ok, res.error
        (local,) = tk.smooth_files(pos, tmp_path / "local", METHOD, output_format="csv")
        assert memory.cat(res.output) == open(local.output, "rb").read()
    finally:
        if memory.exists(root):
            memory.rm(root, recursive=True)


def test_another_fps_redoes_only_the_files_that_used_it(tmp_path):
    """--fps times the files that state no rate; a file with its own rate did not use
    it, and a re-run with another --fps passes over it (its output would be the same)."""
    import numpy as np

    src = tmp_path / "in"
    src.mkdir()
    walk = np.cumsum(np.random.default_rng(0).normal(0, 0.01, (40, 25, 3)), axis=0)
    np.save(src / "bare.npy", walk)  # no rate
    topo = tk.get_topology("kinect_v2")
    tk.save([tk.SkeletonSequence(walk, topo, fps=30.0)], src / "timed.npz")  # its own rate
    out = tmp_path / "out"
    first = tk.smooth_files(src, out, METHOD, fps=25)
    assert all(r.ok for r in first) and _skipped(first) == []
    again = tk.smooth_files(src, out, METHOD, fps=50)
    assert _skipped(again) == [str(src / "timed.npz")]
    assert _skipped(tk.smooth_files(src, out, METHOD, fps=50)) == sorted(
        str(src / n) for n in ("bare.npy", "timed.npz")
    )
    redone = tk.smooth_files(src, out, METHOD)  # no rate given: the bare file again
    assert _skipped(redone) == [str(src / "timed.npz")]


def test_an_input_smoothed_by_two_methods_keeps_both_records(src, tmp_path):
    """kf, then sgf, then kf again into one folder: the third run passes over the kf
    outputs (the manifest keeps a line per input and output)."""
    out = tmp_path / "out"
    inputs = sorted(r.source for r in tk.smooth_files(src, out, "kf"))
    assert _skipped(tk.smooth_files(src, out, "sgf")) == []
    assert _skipped(tk.smooth_files(src, out, "kf")) == inputs
    assert _skipped(tk.smooth_files(src, out, "sgf")) == inputs
    lines = [json.loads(x) for x in (out / MANIFEST_NAME).read_text().splitlines()]
    assert len(lines) == 2 * len(inputs)
    # the latest line of each input is its last: read_entries gives the sgf runs
    assert {e["method"] for e in read_entries(out / MANIFEST_NAME).values()} == {"sgf"}


def test_a_format_typed_or_resolved_is_one_format(src, tmp_path):
    """NTU inputs: ``auto`` reads NTU and writes NTU, as ``-F ntu -f ntu`` does; a re-run
    that only spells the formats out passes over every file."""
    out = tmp_path / "out"
    first = tk.smooth_files(src, out, METHOD)
    inputs = sorted(r.source for r in first)
    assert all(r.ok for r in first)
    for fmt in ({"output_format": "ntu"}, {"input_format": "ntu"},
                {"input_format": "ntu", "output_format": "ntu"}):  # fmt: skip
        assert _skipped(tk.smooth_files(src, out, METHOD, **fmt)) == inputs, fmt
    # another format under its own name is another output; CSV is done once
    assert _skipped(tk.smooth_files(src, out, METHOD, output_format="csv")) == []
    assert _skipped(tk.smooth_files(src, out, METHOD, output_format="csv")) == inputs


def test_formats_compare_as_read_and_written():
    from tobitkf.app.manifest import same_formats

    entry = {"formats": {"input": "ntu", "output": "ntu"},
             "params": {"input_format": "auto", "output_format": "auto"}}  # fmt: skip
    assert same_formats(entry, {"input_format": "auto"}, "ntu")
    assert same_formats(entry, {"input_format": "ntu"}, "ntu")
    assert not same_formats(entry, {"input_format": "csv"}, "ntu")  # another reader
    assert not same_formats(entry, {"input_format": "auto"}, "csv")  # another writer
    # explicit then, auto now: the reader auto picks is not known without reading
    explicit = {**entry, "params": {"input_format": "ntu"}}
    assert same_formats(explicit, {"input_format": "ntu"}, "ntu")
    assert not same_formats(explicit, {"input_format": "auto"}, "ntu")


def test_entries_without_the_formats_compare_them_as_typed(src, tmp_path):
    """A manifest written before the formats were recorded: as before, the typed ones."""
    out = tmp_path / "out"
    inputs = sorted(r.source for r in tk.smooth_files(src, out, METHOD))
    path = out / MANIFEST_NAME
    lines = [json.loads(ln) for ln in path.read_text().splitlines()]
    assert all(e["formats"] == {"input": "ntu", "output": "ntu"} for e in lines)
    path.write_text("".join(json.dumps({**e, "formats": None}) + "\n" for e in lines))
    assert _skipped(tk.smooth_files(src, out, METHOD)) == inputs
    assert _skipped(tk.smooth_files(src, out, METHOD, output_format="ntu")) == []


def test_another_inputs_output_is_neither_replaced_nor_taken_for_done(tmp_path):
    """One folder per subject, each subject's files named alike, smoothed one subject at
    a time into one output folder: the second subject's run must not replace the first's
    results, and a re-run of the first must not pass over outputs that now hold another
    input's result (--overwrite replaced them)."""
    write_ntu_like(tmp_path / "subject1", 2, seed=0, frames=(30, 40))
    write_ntu_like(tmp_path / "subject2", 2, seed=50, frames=(30, 40))  # same names
    out = tmp_path / "out"
    first = tk.smooth_files(tmp_path / "subject1", out, METHOD)
    outputs = {r.output: (out / r.output).read_bytes() for r in first}
    second = tk.smooth_files(tmp_path / "subject2", out, METHOD)
    assert not any(r.ok for r in second)
    assert all("holds the result of" in r.error and "subject1" in r.error for r in second)
    assert {o: (out / o).read_bytes() for o in outputs} == outputs  # nothing lost
    replaced = tk.smooth_files(tmp_path / "subject2", out, METHOD, overwrite=True)
    assert all(r.ok for r in replaced)
    again = tk.smooth_files(tmp_path / "subject1", out, METHOD)
    assert _skipped(again) == [] and not any(r.ok for r in again)
    # the manifest names the input whose result each output holds
    m = Manifest(out)
    assert all("subject2" in m.owner(out / o) for o in outputs)


def test_an_output_whose_sidecar_was_deleted_is_redone(tmp_path):
    """Without its sidecar a CSV output no longer says it is tobitkf's; the manifest
    does, so a re-run redoes it (it used to refuse it as someone else's file, forever)."""
    write_ntu_like(tmp_path / "in", 1, frames=(30, 40))
    out = tmp_path / "out"
    (first,) = tk.smooth_files(tmp_path / "in", out, METHOD, output_format="csv")
    sidecar = (out / first.output).with_suffix(".json")
    sidecar.unlink()
    (again,) = tk.smooth_files(tmp_path / "in", out, METHOD, output_format="csv")
    assert again.ok and not again.extra.get("skipped"), again.error
    assert sidecar.is_file()
    # a CSV there that no run wrote is still left alone
    (tmp_path / "in2").mkdir()
    other = out / "mine.kf.csv"
    other.write_text("a_x,a_y,a_z\n0,0,0\n")
    write_ntu_like(tmp_path / "in2", 1, frames=(30, 40))
    src = next((tmp_path / "in2").rglob("*.skeleton")).rename(tmp_path / "in2" / "mine.skeleton")
    (refused,) = tk.smooth_files(src, out, METHOD, output_format="csv")
    assert not refused.ok and "is not a tobitkf output" in refused.error


def test_a_rerun_parses_the_manifest_once_and_sees_what_changed_it(src, tmp_path, monkeypatch):
    # planning, opening and locking each read the manifest: for 10^5 inputs seconds
    # each. An unchanged file is parsed once; one changed in between is read again
    from tobitkf.app import manifest as mf

    out = tmp_path / "out"
    first = tk.smooth_files(src, out, METHOD)
    calls = []
    real = mf.parse_pairs
    monkeypatch.setattr(mf, "parse_pairs", lambda lines: calls.append(1) or real(lines))
    mf._LAST_READ.clear()
    again = tk.smooth_files(src, out, METHOD)
    assert _skipped(again) == sorted(r.source for r in first)
    assert len(calls) == 1
    # another run's record appended (same size: a changed line of the same length)
    path = out / MANIFEST_NAME
    lines = path.read_text().splitlines()
    entry = json.loads(lines[0])
    entry["params"] = {**entry["params"], "q": 123.0}  # done with other parameters
    lines[0] = json.dumps(entry, sort_keys=True)
    path.write_text("\n".join(lines) + "\n")
    third = tk.smooth_files(src, out, METHOD)
    assert entry["input"] not in _skipped(third) and len(_skipped(third)) == len(first) - 1

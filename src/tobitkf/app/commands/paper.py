"""``tobitkf reproduce`` (the 2020 paper's experiments) and ``tobitkf fit`` (ML noise)."""

from __future__ import annotations

from contextlib import nullcontext
from pathlib import Path
from typing import Any

import click

from tobitkf.app.commands._common import (
    _fail,
    _input_format_option,
    _load_one,
    _need_matplotlib,
    _progress,
    _units_option,
    _writable_folder,
    app,
    console,
    err_console,
)
from tobitkf.core.jsonable import dumps


# --------------------------------------------------------------------------- reproduce
@app.group()
def reproduce():
    """Regenerate the 2020 paper's synthetic results, next to what the paper printed."""


def _show_paper_result(
    result: Any, as_json: bool, outdir: Any, figures: str | None, markdown: str | None = None
) -> None:
    """Print a reproduction result (text, JSON, or Markdown with the name of its function in
    :mod:`tobitkf.paper.markdown`) and write its figures when asked."""
    if as_json:
        click.echo(dumps(result.to_dict()))
    elif markdown:
        from tobitkf.paper import markdown as paper_markdown

        click.echo(getattr(paper_markdown, markdown)(result), nl=False)
    else:  # markup=False: "[min, max]" is text, not a rich style
        console.print(result.format_text(), highlight=False, soft_wrap=True, markup=False)
    if outdir:
        from tobitkf.paper import figures as paper_figures

        for p in getattr(paper_figures, figures)(result, outdir):
            err_console.print(f"wrote {p}")


def _paper_output(out_help: str) -> Any:
    """The output options of a reproduction with figures: ``--json``, ``--markdown`` (next
    to the paper's numbers) and ``--out`` (a folder for the figures, ``out_help``)."""

    def wrap(fn: Any) -> Any:
        fn = click.option(
            "--out", "outdir", type=click.Path(file_okay=False), default=None, help=out_help
        )(fn)
        fn = click.option(
            "--markdown", "as_markdown", is_flag=True, help="Print Markdown, next to the paper's."
        )(fn)
        return click.option("--json", "as_json", is_flag=True, help="Print as JSON.")(fn)

    return wrap


@reproduce.command("covariance-example")
@click.option(
    "--samples",
    default=1_000_000,
    show_default=True,
    type=click.IntRange(1),
    help="Monte Carlo samples for eq. 23.",
)
@click.option("--seed", default=0, show_default=True)
@_paper_output("Write figures (PNG) here.")
def covariance_example_cmd(samples, seed, as_json, as_markdown, outdir):
    """Section 3.4: exact censored covariance vs the standard TKF's vs Monte Carlo."""
    from tobitkf.paper.covariance import covariance_example

    if outdir:
        _need_matplotlib("--out (the figures)")
        _writable_folder(outdir, "the figures")
    result = covariance_example(samples=samples, seed=seed)
    markdown = "covariance_markdown" if as_markdown else None
    _show_paper_result(result, as_json, outdir, "covariance_example_figure", markdown)


@reproduce.command("oscillator")
@click.option(
    "--runs", default=100, show_default=True, type=click.IntRange(1), help="Monte Carlo runs."
)
@click.option(
    "--steps", default=1000, show_default=True, type=click.IntRange(2), help="Time steps per run."
)
@click.option("--seed", default=0, show_default=True, help="First seed.")
@click.option(
    "--seeds",
    default=1,
    show_default=True,
    type=click.IntRange(1, 1000),
    help="Repeat with this many seeds and report the spread.",
)
@_paper_output("Write Fig. 2 and Fig. 3 (PNG) here.")
@click.option(
    "--random-x0",
    is_flag=True,
    help="Draw each run's true start from N(x0, P0) instead of x0 (the paper is ambiguous).",
)
@click.option(
    "--measurement-variance",
    "r",
    default=0.5,
    show_default=True,
    type=click.FloatRange(min=0, min_open=True),
    help="Variance of the measurement noise (the paper's '0.5'; 0.25 reads it as an sd).",
)
def oscillator_cmd(runs, steps, seed, seeds, as_json, as_markdown, outdir, random_x0, r):
    """Section 4.1: Tables 1 and 2 (RMSE and NCI) for TKF, TKF^c and the KF."""
    from tobitkf.paper.oscillator import OscillatorConfig, oscillator_experiment

    if outdir:
        _need_matplotlib("--out (the figures)")
        _writable_folder(outdir, "the figures")
    try:
        config = OscillatorConfig(runs=runs, steps=steps, random_x0=random_x0, r=r)
    except ValueError as exc:
        _fail(str(exc))
    with (
        err_console.status(f"{runs} runs x {steps} steps x {seeds} seed(s)...")
        if err_console.is_terminal
        else nullcontext()
    ):
        result = oscillator_experiment(seed=seed, seeds=seeds, config=config)
    markdown = "oscillator_markdown" if as_markdown else None
    _show_paper_result(result, as_json, outdir, "oscillator_figures", markdown)


@reproduce.command("likelihood")
@click.option(
    "--datasets",
    default=20,
    show_default=True,
    type=click.IntRange(1, 10_000),
    help="Simulated data sets (about 6 s each).",
)
@click.option("--seed", default=100, show_default=True, help="Seed of the first data set.")
@click.option(
    "--limits",
    nargs=2,
    type=float,
    default=(-1.2, 0.7),
    show_default=True,
    help="Clipping limits of the simulated sensor (narrower: more censoring).",
)
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
@click.option("--markdown", "as_markdown", is_flag=True, help="Print a Markdown table.")
def likelihood_cmd(datasets, seed, limits, as_json, as_markdown):
    """Equations 26-29: does maximum likelihood recover q and r of a censored AR(1)?"""
    from tobitkf.paper.likelihood import RecoveryConfig, likelihood_recovery

    try:
        config = RecoveryConfig(lower=limits[0], upper=limits[1])
    except ValueError as exc:
        _fail(str(exc))
    with _progress() as progress:
        task = progress.add_task("fitting", total=datasets, now="")
        result = likelihood_recovery(
            datasets=datasets,
            seed=seed,
            config=config,
            progress=lambda i: progress.update(task, completed=i + 1, now=f"seed {seed + i}"),
        )
    markdown = "recovery_markdown" if as_markdown else None
    _show_paper_result(result, as_json, None, None, markdown)


# --------------------------------------------------------------------------- fit
@app.command()
@click.argument("paths", nargs=-1, required=True, type=click.Path(exists=True, dir_okay=False))
@click.option("--per-joint", is_flag=True, help="One Q per joint instead of one shared Q.")
@click.option(
    "--structure",
    "q_structure",
    default="scalar",
    show_default=True,
    type=click.Choice(["scalar", "diagonal", "full"]),
    help="Structure of Q.",
)
@click.option("--fit-r", is_flag=True, help="Also estimate R (R = r I).")
@click.option(
    "--form",
    default="corrected",
    show_default=True,
    type=click.Choice(["corrected", "standard", "gaussian"]),
    help="Likelihood: censored with S (corrected), with R (standard), or plain KF.",
)
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
@click.option("--markdown", "as_markdown", is_flag=True, help="Print one Markdown row per fit.")
@_input_format_option("--format", help="Input format of every PATH.")
@_units_option(
    "Length unit of the PATHs that state none (a CSV without its sidecar, read as metres "
    "in 3-D; a .npy array), e.g. mm: the fit is in metres."
)
def fit(paths, per_joint, q_structure, fit_r, form, as_json, as_markdown, input_format, units):
    """Maximum-likelihood estimate of the process noise Q of skeleton recordings.

    Q and R are variances of positions in m² (Q per frame step of the recording); a
    recording in centimetres or millimetres is fitted in metres. 3-D skeletons only."""
    from tobitkf.smoothing.fit import fit_skeleton_noise

    results: dict[str, Any] = {}
    rows: list[tuple[str, Any]] = []  # (label, fit) for --markdown
    quiet = as_json or as_markdown
    for path in paths:
        seq = _load_one(path, "recording", input_format, units=units)
        kwargs: dict[str, Any] = {
            "per_joint": per_joint,
            "q_structure": q_structure,
            "fit_r": fit_r,
            "form": form,
        }
        if form == "gaussian":
            kwargs["c"] = None
        try:
            if per_joint:  # one fit per joint, with a progress display on a terminal
                res = {}
                with _progress(quiet=quiet) as progress:
                    task = progress.add_task(f"fitting {path}", total=seq.n_joints, now="")
                    for j, joint in enumerate(seq.joint_names):
                        progress.update(task, now=joint)
                        try:
                            res.update(fit_skeleton_noise(seq, joints=[j], **kwargs))
                        except ValueError as exc:  # fewer than two observed frames
                            if "at least two observed" not in str(exc):
                                raise
                        progress.advance(task)
                if not res:
                    raise ValueError("no joint has at least two observed frames")
            else:
                with console.status(f"fitting {path}...") if not quiet else nullcontext():
                    res = fit_skeleton_noise(seq, **kwargs)
        except ValueError as exc:
            _fail(f"{path}: {exc}")
        results[path] = (
            {k: v.to_dict() for k, v in res.items()} if isinstance(res, dict) else res.to_dict()
        )
        name = Path(path).name
        rows += (
            [(f"{name}: {joint}", r) for joint, r in res.items()]
            if isinstance(res, dict)
            else [(name, res)]
        )
        if not quiet:
            console.rule(f"[bold]{path}")
            console.print("Q and R: position variances in m² (Q per frame step)")
            if isinstance(res, dict):
                for joint, r in res.items():
                    console.print(f"[bold]{joint}[/bold]")
                    console.print(r.format_text(), highlight=False)
            else:
                console.print(res.format_text(), highlight=False)
    if as_json:
        click.echo(dumps(results))
    elif as_markdown:
        from tobitkf.paper.markdown import noise_fit_markdown

        click.echo(noise_fit_markdown(rows), nl=False)

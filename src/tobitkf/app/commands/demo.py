"""``tobitkf demo``: the built-in example, smoothed and reported."""

from __future__ import annotations

import click

from tobitkf.app.commands._common import (
    _noticing_compiles,
    _writable_folder,
    app,
    console,
    err_console,
)


# --------------------------------------------------------------------------- demo
@app.command()
@click.option(
    "-o",
    "--out",
    "outdir",
    default="demo-output",
    show_default=True,
    type=click.Path(file_okay=False),
    help="Folder for the recordings and report.",
)
@click.option("--seed", default=0, show_default=True, type=click.IntRange(min=0))
@click.option("--no-gif", is_flag=True, help="Leave out the skeleton animation.")
@_noticing_compiles
def demo(outdir, seed, no_gif):
    """The main job end to end on the built-in synthetic recording (no files needed)."""
    from tobitkf.app.demo import run_demo

    try:
        import matplotlib  # noqa: F401

        report = True
    except ImportError:  # the recordings and the table without the report
        report = False
        err_console.print(
            "the demo's report needs matplotlib, which is not installed: pip install "
            "'tobitkf[plot]'; writing the recordings and the table without it",
            markup=False,
        )
    _writable_folder(outdir, "the demo's files")  # before generating and smoothing
    with console.status("generating, smoothing, scoring, drawing..."):
        result = run_demo(outdir, seed=seed, gif=not no_gif, report=report)
    console.print("[bold]RMSE against the known truth, by glitch type (cm)[/bold]")
    console.print(result.table.to_text(), highlight=False, soft_wrap=True)
    for f in result.files:
        console.print(f"wrote {f}")
    if result.report is not None:
        console.print(f"report: {result.report.resolve()}")

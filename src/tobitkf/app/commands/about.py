"""``tobitkf info`` (what a reader found in a file) and ``tobitkf methods`` (the registry)."""

from __future__ import annotations

import click
from rich.markup import escape

from tobitkf.app.commands._common import (
    _fail,
    _fmt,
    _input_format_option,
    _print_table,
    app,
    console,
)
from tobitkf.core.jsonable import dumps


# --------------------------------------------------------------------------- info
@app.command()
@click.argument("path", type=click.Path(exists=True))
@_input_format_option("--format", help="Input format.")
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
def info(path, input_format, as_json):
    """Describe what the reader finds in a recording."""
    from tobitkf.app.info import describe

    try:
        report = describe(path, format=input_format)
    except (ValueError, OSError, ImportError) as exc:
        _fail(str(exc))
    if as_json:
        click.echo(dumps(report))
        return
    console.print(f"[bold]{path}[/bold]  format: {report['format']}  bodies: {report['bodies']}")
    for k, body in enumerate(report["sequences"], start=1):
        label = f"body {k}" + ("" if body["body_id"] is None else f" (id {body['body_id']})")
        console.print(
            f"{escape(label)}: {body['frames']} frames, {body['joints']} joints "
            f"({body['topology']}), {_rate(body)}, missing in the file "
            f"{_fmt(body['missing_percent'])} %"
        )
        if body.get("dt_range"):
            lo, med, hi = body["dt_range"]
            console.print(f"  time steps: min {lo:.4f} s, median {med:.4f} s, max {hi:.4f} s")
        console.print(f"  units: {_units(body)}")
        if body.get("size_problem"):
            console.print(f"  [red]size[/red]: {escape(body['size_problem'])}")
        if body.get("size_note"):
            console.print(f"  [yellow]size[/yellow]: {escape(body['size_note'])}")
        for note in body["reader_warnings"]:
            console.print(f"  [yellow]reader[/yellow]: {escape(note)}")
        if body.get("tracking_states"):
            states = ", ".join(f"{k}: {v}" for k, v in body["tracking_states"].items())
            console.print(f"  tracking states: {states}")
        rows = [[j["joint"], j["largest_jump"], j["frame"], j["missing"]] for j in body["jumps"]]
        _print_table(
            "largest frame-to-frame jump per joint",
            ["joint", f"jump ({body['units'] or 'units'})", "at frame", "missing"],
            rows,
            digits=3,
        )


def _units(body: dict) -> str:
    units = body["units"] or "unknown"
    if body["units_stated"]:
        return units
    return f"{units} (the file states none; smooth, evaluate and report take --units)"


def _rate(body: dict) -> str:
    if body["fps"] is None and not body["has_timestamps"]:
        return "no frame rate in the file (tobitkf smooth takes 30 fps, or --fps)"
    rate = "timestamps" if body["fps"] is None else f"rate {_fmt(body['fps'])} Hz"
    return f"{rate}, duration {_fmt(body['duration_s'])} s"


# --------------------------------------------------------------------------- methods
@app.command()
def methods():
    """List the smoothing methods, what they are and their default parameters."""
    from tobitkf.smoothing.api import methods as registered

    rows = []
    for name, spec in sorted(registered().items()):
        kind = ("causal" if spec.is_causal() else "offline") + (", +rts" if spec.offline_ok else "")
        defaults = ", ".join(
            f"{k}={v}" + (f" {_PARAM_UNITS[k]}" if k in _PARAM_UNITS and v is not None else "")
            for k, v in spec.defaults.items()
        )
        rows.append([name, kind, spec.description, defaults])
    _print_table("smoothing methods", ["method", "runs", "what it is", "defaults"], rows)
    console.print(
        "units: positions in metres; q, r are variances (m², q per 1/30 s step), c and "
        "limits in metres, speeds in m/s, times in seconds, windows in frames, cut-offs in Hz"
    )


#: units of the built-in methods' parameters, shown by `tobitkf methods`
_PARAM_UNITS = {
    "q": "m²/step",
    "r": "m²",
    "c": "m",
    "c_horizontal": "m",
    "c_vertical": "m",
    "lower": "m",
    "upper": "m",
    "v_max": "m/s",
    "speed_sd": "m/s",
    "noise_sd": "m",
    "margin": "m",
    "bone_tol_abs": "m",
    "tau": "s",
    "min_run": "s",
    "window": "frames",
    "lookback": "frames",
    "mincutoff": "Hz",
    "dcutoff": "Hz",
    "jitter_radius": "m",
    "max_deviation_radius": "m",
}

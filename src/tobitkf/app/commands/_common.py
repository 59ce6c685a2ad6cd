"""What every command shares: the click group, consoles, tables, progress, checks."""

from __future__ import annotations

import functools
import os
import signal
import tempfile
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

import click
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table
from rich.text import Text

console = Console()
_OWN_CONSOLE = console  # (a console put in its place, by a test or an embedding, is kept)


def _fit_console() -> None:
    """Set the table console's width from the environment of this invocation, not of the
    import: ``COLUMNS`` when set; else the terminal's own; else (files and pipes) 160, so
    a log gets whole tables, not 80-column cuts, and lines of text are not wrapped at
    all (soft wrap: a method's parameters stay on their line, not cut in the middle of
    a dict). rich reads ``COLUMNS`` once, when the console is made; a second ``main()``
    in one process (tests, notebooks) would keep the first one's width."""
    own = _OWN_CONSOLE
    columns = os.environ.get("COLUMNS", "")
    own.soft_wrap = False
    if columns.isdigit() and int(columns) > 0:
        own.width = int(columns)
    else:
        own.width = None  # rich asks the terminal at each print
        if not own.is_terminal:
            own.width = 160
            own.soft_wrap = True


_fit_console()
# messages name files: never cut a line (a path split in two is neither found by grep in a
# log nor copied whole from a terminal, which wraps long lines itself)
err_console = Console(stderr=True, soft_wrap=True)


def _fail(message: str) -> None:
    raise click.ClickException(message)


def _fmt(value: Any, digits: int = 2) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        if value != value:  # NaN
            return "-"
        return f"{value:.{digits}f}"
    return str(value)


def _print_table(title: str, columns: list[str], rows: list[list[Any]], digits: int = 2) -> None:
    table = Table()  # the title is printed on its own line: a table's is padded
    for i, col in enumerate(columns):
        # long file names fold onto a second line instead of being cut to "JointPositi…"
        table.add_column(col, justify="left" if i == 0 else "right", overflow="fold")
    for row in rows:  # as Text: a method's label atkf[c=0.1] is not markup
        table.add_row(*[Text(_fmt(v, digits)) for v in row])
    if rows and _table_width(table, columns, rows, digits) > console.width:
        # a terminal too narrow for the table: its columns would be squeezed until every
        # header and name breaks mid-word; one block per row instead, a field per line
        console.print(Text(title, style="italic"))
        for row in rows:
            console.print()
            for col, v in zip(columns, row, strict=True):
                console.print(Text.assemble((f"{col}: ", "bold"), _fmt(v, digits)))
        return
    console.print(Text(title, style="italic"))
    console.print(table)


#: the narrowest the first column (file names) may fold to before a table is printed as
#: blocks instead
NAME_FOLD = 18


def _table_width(table: Table, columns: list[str], rows: list[list[Any]], digits: int) -> int:
    """The width ``table`` needs with its first column folded to at most ``NAME_FOLD``
    characters and every other column whole."""
    natural = console.measure(table, options=console.options.update_width(10_000)).maximum
    first = max(len(columns[0]), *(len(_fmt(r[0], digits)) for r in rows))
    return natural - first + min(first, NAME_FOLD)


class _RegistryChoice(click.Choice):
    """A ``click.Choice`` whose values are read from a registry when first needed, so
    that a method or format registered by a plugin is a valid choice and ``--help`` of
    the other commands does not pay for loading the registry."""

    def __init__(self, load: Any, extra: tuple[str, ...] = ()) -> None:
        self._load, self._extra = load, extra
        self.case_sensitive = True

    @property
    def choices(self) -> tuple[str, ...]:  # type: ignore[override]
        return (*self._extra, *self._load())


class _ListsChoices(click.Option):
    """An option whose help ends with its choices, read when the help is shown: a long
    list wraps with the help text in a narrow terminal, where click's ``[a|b|c]`` metavar
    would be one unbroken line (the option shows ``metavar`` instead)."""

    def get_help_record(self, ctx: click.Context) -> tuple[str, str] | None:
        base = self.help
        self.help = f"{base or ''} One of: {', '.join(self.type.choices)}.".strip()
        try:
            return super().get_help_record(ctx)
        finally:
            self.help = base


def _method_names() -> list[str]:
    from tobitkf.smoothing.api import method_names

    return method_names()


def _writable_formats() -> list[str]:
    from tobitkf.io import writable_formats

    return writable_formats()


def _readable_formats() -> list[str]:
    from tobitkf.io import formats

    return sorted(n for n, spec in formats().items() if spec.reader is not None)


def _input_format_option(
    *names: str, dest: str = "input_format", help: str = "Input format of every TRACK/PATH."
) -> Any:
    return click.option(
        *names,
        dest,
        default="auto",
        show_default=True,
        type=_RegistryChoice(_readable_formats, extra=("auto",)),
        metavar="FORMAT",
        cls=_ListsChoices,
        help=help + " Auto-detected by default.",
    )


def _finite(value: float | None, name: str) -> float | None:
    if value is not None and value != value:  # NaN passes a range check
        raise click.BadParameter(f"{name} must be a number, got nan")
    return value


def _topology_name(value: str | None) -> str | None:
    """``--topology``: a known skeleton's canonical name (aliases such as h36m accepted)."""
    if value is None:
        return None
    from tobitkf.skeleton.topology import get_topology

    try:
        return get_topology(value).name
    except KeyError as exc:
        raise click.BadParameter(str(exc.args[0]), param_hint="--topology") from None


def _fps_option(help: str) -> Any:
    """``--fps``: the frame rate of inputs that state none."""
    return click.option(
        "--fps",
        type=click.FloatRange(min=1e-3, max=1e5),  # the readers' plausible rates (io._text)
        callback=lambda _ctx, _param, v: _finite(v, "--fps"),
        help=help,
    )


def _topology_option(help: str) -> Any:
    """``--topology``: the skeleton of inputs that name none."""
    return click.option(
        "--topology",
        metavar="NAME",
        callback=lambda _ctx, _param, v: _topology_name(v),
        help=help,
    )


def _units_option(help: str) -> Any:
    """``--units``: the length unit of inputs that state none."""
    from tobitkf.skeleton.sequence import KNOWN_UNITS

    return click.option("--units", type=click.Choice(sorted(KNOWN_UNITS)), help=help)


def _os_reason(exc: OSError) -> str:
    if isinstance(exc, PermissionError):
        return "permission denied"
    if isinstance(exc, FileExistsError):
        return "a file of that name exists (not a folder)"
    if isinstance(exc, NotADirectoryError):
        return "part of the path is a file, not a folder"
    return exc.strerror or str(exc)


def _writable_folder(folder: str | Path, what: str) -> Path:
    """Create ``folder`` if needed and check that a file can be written in it, before any
    work is done: one clear message instead of a traceback after minutes of work."""
    path = Path(folder)
    try:
        path.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=path, prefix=".tobitkf-write-check-")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        _fail(f"cannot write {what} in {path}: {_os_reason(exc)}")
    return path


def _writable_file(path: str | Path, what: str) -> Path:
    """Check that ``path`` can be written (its folder writable, no folder in the way)."""
    target = Path(path)
    if target.is_dir():
        _fail(f"cannot write {what} {target}: it is a folder")
    _writable_folder(target.parent, what)
    return target


@contextmanager
def _compile_notice(what: str = "the smoothers' kernels"):
    """Say so once when kernels start compiling inside the block (a fresh machine, or
    after an upgrade: minutes of silence otherwise)."""
    from tobitkf.smoothing.warmup import on_first_compile

    def notice() -> None:
        err_console.print(
            f"compiling {what} for this machine: seconds to a few minutes, first run only "
            "(they are cached for later runs; `tobitkf warmup` does it ahead)"
        )

    with on_first_compile(notice):
        yield


def _noticing_compiles(command):
    """A command that runs methods, with :func:`_compile_notice` around it (the
    decorator nearest to ``def``, under click's)."""

    @functools.wraps(command)
    def run(*args, **kwargs):
        with _compile_notice():
            return command(*args, **kwargs)

    return run


def _need_matplotlib(what: str) -> None:
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        _fail(f"{what} needs matplotlib, which is not installed: pip install 'tobitkf[plot]'")


#: narrowest terminal (columns) whose progress line has a bar
_BAR_MIN_WIDTH = 80


@contextmanager
def _progress(quiet: bool = False, field: str = "{task.fields[now]}", transient: bool = True):
    """A progress display on stderr, shown only on a terminal (pipes and logs get none);
    a terminal narrower than :data:`_BAR_MIN_WIDTH` gets no bar and a shorter name, so
    that the counts and the elapsed time fit on the line."""
    from rich.table import Column

    wide = err_console.width >= _BAR_MIN_WIDTH
    # narrow: no bar, and the name cut to what the counts and the time leave
    name = None if wide else Column(width=max(8, err_console.width - 42), no_wrap=True)
    with Progress(
        TextColumn("[bold]{task.description}", table_column=name),
        *([BarColumn()] if wide else []),
        MofNCompleteColumn(),
        TextColumn(field),
        TimeElapsedColumn(),
        console=err_console,
        transient=transient,
        disable=quiet or not err_console.is_terminal,
    ) as progress:
        yield progress


def _ticking(specs: list[Any], progress: Any, task: Any) -> list[Any]:
    """Method specs that advance ``task`` after each method has run (name shown)."""
    from tobitkf.evaluation.evaluate import resolve_method

    wrapped = []
    for spec in specs:
        label, fn = resolve_method(spec)

        def run(seq, _fn=fn, _label=label):
            progress.update(task, now=_label)
            out = _fn(seq)
            progress.advance(task)
            return out

        wrapped.append((label, run))
    return wrapped


@contextmanager
def _sigterm_as_interrupt():
    """SIGTERM stops a run like Ctrl-C does (workers terminated, summary printed)."""

    def handler(signum, frame):
        raise KeyboardInterrupt

    try:
        previous = signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread (e.g. a test runner's thread): leave it
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _check_cluster_options(cluster: str | None, workers: int | None, jobs: int) -> None:
    if workers is not None and cluster != "local":
        raise click.BadParameter("goes with --cluster local", param_hint="--workers")
    if cluster is not None and jobs != 1:
        raise click.BadParameter(
            "is the local process pool; with --cluster the cluster's workers run the files",
            param_hint="--jobs",
        )


@contextmanager
def _dask_client(cluster: str | None, workers: int | None):
    """A Dask client for --cluster (None without it), with a clear message when Dask is
    missing or the scheduler cannot be reached."""
    if cluster is None:
        yield None
        return
    from tobitkf.app.cluster import connect

    with ExitStack() as stack:
        try:
            client = stack.enter_context(connect(cluster, workers))
        except ImportError as exc:
            _fail(str(exc))
        except OSError as exc:  # timeouts included: no scheduler there
            _fail(f"cannot connect to the Dask scheduler at {cluster}: {exc}")
        except ValueError as exc:  # not an address
            _fail(
                f"--cluster {cluster}: {exc}; expected a scheduler address (tcp://host:8786), "
                "a scheduler file (*.json) or local"
            )
        yield client


def _parse_params(params: tuple[str, ...]) -> dict[str, Any]:
    from tobitkf.app.batch import parse_param

    out: dict[str, Any] = {}
    for text in params:
        try:
            key, value = parse_param(text)
        except ValueError as exc:
            raise click.BadParameter(str(exc), param_hint="--param") from exc
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            value = {**out[key], **value}  # -p v_max=hands:6 -p v_max=arms:4: both
        out[key] = value
    return out


class _InputPath(click.Path):
    """A path that must exist, or an fsspec URL (``s3://...``), checked when listed."""

    def convert(self, value, param, ctx):
        if isinstance(value, str) and "://" in value:
            return value
        return super().convert(value, param, ctx)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="tobitkf")
def app() -> None:
    """Tobit Kalman filtering of censored measurements, and skeleton-track smoothing."""
    _fit_console()


def _load_one(
    path: str,
    what: str,
    input_format: str = "auto",
    *,
    fps: float | None = None,
    topology: str | None = None,
    units: str | None = None,
):
    """The first body of ``path``, with ``--fps`` / ``--topology`` / ``--units`` where the
    file states no rate / names no skeleton / states no length unit
    (:func:`tobitkf.io.unstated.with_unstated`)."""
    from tobitkf.app.batch import readable_problem
    from tobitkf.io import load
    from tobitkf.io.unstated import with_unstated

    problem = readable_problem(path)
    if problem:
        _fail(f"{what} {path}: {problem}")
    try:
        seqs = load(path, format=input_format)
    except (ValueError, OSError, ImportError) as exc:
        _fail(f"cannot read {what} {path}: {exc}")
    try:
        seqs = with_unstated(seqs, fps=fps, topology=topology, option="--topology", units=units)
    except ValueError as exc:
        _fail(f"{what} {path}: {exc}")
    if not seqs:
        _fail(f"{what} {path} holds no skeleton")
    if len(seqs) > 1:
        err_console.print(f"{path}: {len(seqs)} bodies; using the first ({seqs[0].body_id})")
    return seqs[0]

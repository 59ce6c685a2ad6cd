"""``python -m tobitkf``: the command-line tool."""

from tobitkf.app.cli import main

if __name__ == "__main__":
    raise SystemExit(main())

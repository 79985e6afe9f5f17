"""The ``cornerslam`` command (console script and ``python -m cornerslam_cli``): Ctrl-C while the
command line is still being imported (its first few tenths of a second: numpy, click, the readers)
exits 130 with the one line it gives once running, instead of Python's traceback and exit 1."""

import sys


def main() -> None:
    try:
        from .cli import main as cli
    except KeyboardInterrupt:
        sys.stderr.write("interrupted: no output written (an earlier output there, if any, is kept)\n")
        sys.exit(130)
    cli()

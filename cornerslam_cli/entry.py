"""The ``cornerslam`` command (console script and ``python -m cornerslam_cli``): Ctrl-C while the
command line is still being imported (its first few tenths of a second: numpy, click, the readers)
exits 130 with the one line it gives once running, instead of Python's traceback and exit 1; and once
the command has ended, Ctrl-C or SIGTERM while the interpreter shuts down (freeing a long run's memory
takes a moment) no longer kills it without a word — or with "Exception ignored … KeyboardInterrupt" —
after its output is complete: its exit status stands."""

import signal
import sys


def main() -> None:
    try:
        from .cli import main as cli
    except KeyboardInterrupt:
        sys.stderr.write("interrupted: no output written (an earlier output there, if any, is kept)\n")
        sys.exit(130)
    try:
        cli()
    finally:  # the command's own end (exit status, its last line) is said: nothing left to interrupt
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_IGN)

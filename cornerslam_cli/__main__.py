"""``python -m cornerslam_cli`` = the ``cornerslam`` command."""

from .cli import main

main()

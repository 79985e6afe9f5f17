"""``python -m cornerslam_cli`` = the ``cornerslam`` command."""

from .entry import main

main()

"""``python -m peg_ctrl``: the ``peg-sim`` command line."""

import sys

from peg_ctrl.cli import main

if __name__ == "__main__":
    sys.exit(main())

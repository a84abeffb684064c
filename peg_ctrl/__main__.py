import sys

from peg_ctrl.cli import main

sys.exit(main())

"""The ``peg-sim`` command line (:mod:`~peg_ctrl.cli.app`) and the teleoperation window
(:mod:`~peg_ctrl.cli.teleop_window`): the top layer, which may import every other.
"""

from peg_ctrl.cli.app import main

__all__ = ["main"]

"""The Gymnasium environment ``peg_ctrl/PegInsertion-v0`` (:mod:`~peg_ctrl.gym.env`),
registered when ``peg_ctrl`` is imported.

May import the run layer and everything below it; never teleoperation, experiments, tools or
the command line.
"""

"""Running episodes: the control loop, its recorders and logs, episodes and batches of them.

:mod:`~peg_ctrl.run.loop` steps a task, a controller and the physics; :mod:`~peg_ctrl.run.episode`
builds one episode from its config and writes its record (:mod:`~peg_ctrl.run.result`, the
record and its fields' metadata; :mod:`~peg_ctrl.run.episode_log`,
:mod:`~peg_ctrl.run.recorders`, :mod:`~peg_ctrl.run.plots`); :mod:`~peg_ctrl.run.batch` and
:mod:`~peg_ctrl.run.workers` run many in worker processes; :mod:`~peg_ctrl.run.tracker` drives a
controller along a reference without a task's phases.

May import: ``peg_ctrl.tasks``, ``peg_ctrl.controllers``, ``peg_ctrl.planners``,
``peg_ctrl.sim`` and the foundation modules. Never the experiments, tools, Gymnasium env,
teleoperation or command line above it.
"""

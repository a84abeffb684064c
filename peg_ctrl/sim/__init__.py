"""The simulated world and how it is read: the lowest layer above the foundation modules.

Asset generation (:mod:`~peg_ctrl.sim.assets`, :mod:`~peg_ctrl.sim.menagerie`), the scene and
its model (:mod:`~peg_ctrl.sim.scene`), the physics profiles (:mod:`~peg_ctrl.sim.physics`), the
jaw's calibration (:mod:`~peg_ctrl.sim.jaw`), state reading and the wrist sensor
(:mod:`~peg_ctrl.sim.state`, :mod:`~peg_ctrl.sim.sensing`) with its noise model
(:mod:`~peg_ctrl.sim.ft_model`), rotations, the held-peg start
(:mod:`~peg_ctrl.sim.grasp_start`), the belief a task hands its controller
(:mod:`~peg_ctrl.sim.belief`) and the contact model's validity studies
(:mod:`~peg_ctrl.sim.validity`).

May import: the foundation modules (``peg_ctrl.errors``, ``io``, ``config``, ``commands``,
``timing``, ``progress``) only. Everything else imports this.
"""

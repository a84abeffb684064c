"""Tools around the simulator: the loop's overhead benchmark (:mod:`~peg_ctrl.tools.bench`),
the physics-profile check (:mod:`~peg_ctrl.tools.profile_check`), the contact-validity report
(:mod:`~peg_ctrl.tools.validity_report`), the contact cross-check against Drake
(:mod:`~peg_ctrl.tools.crosscheck`) and the replay of a recorded run (:mod:`~peg_ctrl.tools.replay`).

May import every layer below the command line: experiments, the run layer, tasks, controllers,
planners, the simulator and the foundation modules.
"""

"""peg_ctrl: a physics-faithful peg-in-hole simulator in MuJoCo and a controller research framework.

Importing the package registers the Gymnasium environment ``peg_ctrl/PegInsertion-v0``
(:mod:`peg_ctrl.gym_env`, imported only when the environment is made).
"""

from gymnasium.envs.registration import register as _register
from gymnasium.envs.registration import registry as _registry

__version__ = "0.1.0"

if "peg_ctrl/PegInsertion-v0" not in _registry:
    _register(id="peg_ctrl/PegInsertion-v0", entry_point="peg_ctrl.gym_env:PegInsertionEnv")

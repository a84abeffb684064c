"""The touches the contact strategies are scripts of, one module each: a :class:`Landing` (a
force-controlled descent that stops on whatever it meets, read from the pose), the
:class:`RockCalibration` (the peg's tilt in the hand from three landings on the face), the
:class:`Centring` (the end pushed against the mouth's walls: :class:`WallPush`) and its pressed
circle (:class:`PressedCircle`), the :class:`ProbeSearch` (landings and bearing presses a
belief chooses until the end is over the bore) and the :class:`SideTouches` (the end against the
block's sides, straight and turned). ``probe`` and ``locate`` play them (docs/contact_real.md);
each takes the strategy that plays it as a :class:`ProbeHost`.
"""

from peg_ctrl.tasks.strategies.skills.centring import Centring, PressedCircle, WallPush
from peg_ctrl.tasks.strategies.skills.common import LAND_AXES, NO_AXES, PRESS_AXES, SLIDE_AXES
from peg_ctrl.tasks.strategies.skills.landing import Landing, ProbeHost
from peg_ctrl.tasks.strategies.skills.rock import PAD_NORMAL, RockCalibration, upright
from peg_ctrl.tasks.strategies.skills.search import ProbeSearch
from peg_ctrl.tasks.strategies.skills.side_touch import SideTouches

__all__ = [
    "LAND_AXES",
    "NO_AXES",
    "PRESS_AXES",
    "SLIDE_AXES",
    "PAD_NORMAL",
    "Centring",
    "Landing",
    "PressedCircle",
    "ProbeHost",
    "ProbeSearch",
    "RockCalibration",
    "SideTouches",
    "WallPush",
    "upright",
]

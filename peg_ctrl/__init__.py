"""peg_ctrl: a physics-faithful peg-in-hole simulator in MuJoCo and a controller research framework."""

__version__ = "0.1.0"

"""Trajectory planners that any controller can track (filled by the autonomous-mode work)."""

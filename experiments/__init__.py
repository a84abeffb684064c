"""Experiment configurations and the sweep runner."""

"""The ``bench`` command: the report's experiments, MRT against the alternatives."""

from .experiments import EXPERIMENTS, run_experiment, summary_line

__all__ = ["EXPERIMENTS", "run_experiment", "summary_line"]

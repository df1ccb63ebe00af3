"""The ``bench`` command: the report's experiments, MRT against the alternatives.

- :mod:`.experiments`: what each experiment sweeps (points, settings, methods);
- :mod:`.measure`: how one point is measured (warm-up, alternating timed
  rounds, converged reference, equal-time full renders) into CSV rows;
  :mod:`.measure_denoise` the same for the ``denoise`` experiment's points;
- :mod:`.records`: what a point records (timed runs, rows, images), and
  :mod:`.memory` its peak memory;
- :mod:`.analysis`: the CSV, the verdicts and the markdown tables;
- :mod:`.plots`: the plots and pictures (matplotlib);
- :mod:`.run`: one experiment end to end (:func:`run_experiment`).
"""

from .experiments import EXPERIMENTS
from .run import ExperimentResult, run_experiment, summary_line

__all__ = ["EXPERIMENTS", "ExperimentResult", "run_experiment", "summary_line"]

"""The evaluation toolkit (paper section III-C), modelled on the GOT-10k toolkit.

- :mod:`.metrics`: AO, SR, ACE, success / precision curves (pure functions over arrays);
- :mod:`.results`: plain-text per-sequence result files;
- :mod:`.experiment`: :class:`Experiment` (run trackers on a split with restarts or one pass,
  3D or 2D only with the null estimator "none", report), :func:`evaluate_2d`;
- :mod:`.plots`: success / precision plots and 3D trajectories (matplotlib, optional);
- :mod:`.draw`: overlay drawing and GIF / MP4 writing.
"""
from .experiment import Experiment, TrackerSpec, evaluate_2d, run_sequence
from .metrics import (LostScore, OverallScore, SequenceScore, average_scores, precision_curve, score_lost,
                      score_sequence, success_curve)

__all__ = ["Experiment", "TrackerSpec", "run_sequence", "evaluate_2d", "SequenceScore", "OverallScore",
           "LostScore", "average_scores", "precision_curve", "score_lost", "score_sequence", "success_curve"]

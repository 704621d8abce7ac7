"""The evaluation toolkit (paper section III-C), modelled on the GOT-10k toolkit.

- :mod:`.metrics`: AO, SR, ACE, success / precision curves (pure functions over arrays);
- :mod:`.results`: plain-text per-sequence result files;
- :mod:`.experiment`: :class:`Experiment` (run trackers on a split with restarts, report);
- :mod:`.plots`: success / precision plots and 3D trajectories (matplotlib, optional);
- :mod:`.draw`: overlay drawing and GIF / MP4 writing.
"""
from .experiment import Experiment, TrackerSpec, run_sequence
from .metrics import SequenceScore, OverallScore, average_scores, precision_curve, score_sequence, success_curve

__all__ = ["Experiment", "TrackerSpec", "run_sequence", "SequenceScore", "OverallScore", "average_scores",
           "precision_curve", "score_sequence", "success_curve"]

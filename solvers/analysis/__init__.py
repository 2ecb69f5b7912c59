"""Simulation versus reality: name the physics a robot's rigid model leaves out.

``analyze(rec)`` takes a :class:`solvers.recording.RecordingData` and returns the
``analysis-report/1`` document; ``render_text(report)`` its human form. See docs/analysis.md.

Modules: ``kinematics`` (TCP twists of every DH parameter), ``baseline`` (the rigid fit of
each recording kind), ``effects`` (the candidate library and its regressors), ``selection``
(linear algebra: held-out RMS, F-test, Holm), ``locate`` (where the mismatch is, structure
groups), ``report`` (the pipeline), ``text`` (plain words), ``blind`` (the blind DH
recalibration used as a yardstick).
"""

from solvers.analysis.report import FORMAT, analyze
from solvers.analysis.text import render_text

__all__ = ["FORMAT", "analyze", "render_text"]

"""Evaluation of the deck-pose estimators: the papers' Stewart-platform experiments and sweeps.

:mod:`agents.evaluation.estimators` runs a scenario and scores every estimator (tables),
:mod:`agents.evaluation.plots` draws the papers' figures, :mod:`agents.evaluation.sweep` plots
the errors against height, ToF noise, deck tilt and lens distortion.  The command line is
``deck-landing evaluate estimators --scenario NAME`` and ``deck-landing evaluate sweep``.
:mod:`~agents.evaluation.landing` and :mod:`~agents.evaluation.approach` evaluate policies over
seeds: two configurations of one pipeline (:mod:`~agents.evaluation.pipeline`: one record in
:mod:`~agents.evaluation.records`, one episode loop, one summary and table in
:mod:`~agents.evaluation.summary`), run by :mod:`~agents.evaluation.runner` (serial or Ray).
The committed figures are the result summaries of :mod:`~agents.evaluation.results`
(``configs/results/*.json``).
"""

from __future__ import annotations

#: the conditions ``evaluate sweep`` can vary (see :mod:`agents.evaluation.sweep`)
SWEEP_PARAMETERS: tuple[str, ...] = ("height", "tof_noise", "pixel_noise", "tilt", "k1")

__all__ = ["SWEEP_PARAMETERS"]

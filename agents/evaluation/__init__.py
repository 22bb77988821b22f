"""Evaluation of the deck-pose estimators: the papers' Stewart-platform experiments and sweeps.

:mod:`agents.evaluation.estimators` runs a scenario and scores every estimator (tables),
:mod:`agents.evaluation.plots` draws the papers' figures, :mod:`agents.evaluation.sweep` plots
the errors against height, ToF noise, deck tilt and lens distortion.  The command line is
``deck-landing evaluate estimators --scenario NAME`` and ``deck-landing evaluate sweep``.
"""

from __future__ import annotations

from agents.cli_args import parse_overrides as _parse_overrides

#: the conditions ``evaluate sweep`` can vary (see :mod:`agents.evaluation.sweep`)
SWEEP_PARAMETERS: tuple[str, ...] = ("height", "tof_noise", "pixel_noise", "tilt", "k1")

__all__ = ["SWEEP_PARAMETERS", "_parse_overrides"]

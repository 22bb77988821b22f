"""The deck ahead, from its past alone (pure NumPy, as the rest of :mod:`estimation`).

* :mod:`~estimation.anticipation.linear_predictors`: direct multi-horizon linear (Wiener)
  predictors with their error: the deck's tilt a descent ahead from the drone's own estimates
  (:class:`~estimation.anticipation.linear_predictors.LinearTiltPredictor`), or several
  channels seconds ahead from a record such as the ship's HMS
  (:class:`~estimation.anticipation.linear_predictors.LinearMotionPredictor`);
* :mod:`~estimation.anticipation.stopping`: the optimal-stopping value of waiting for a
  better chance than the one predicted now.
"""

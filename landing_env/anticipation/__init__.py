"""The deck ahead in the simulated world, by its source and horizon.

* Onboard, a descent ahead (1-2 s): the deck-motion history the drone observes
  (:mod:`~landing_env.anticipation.deck_history`) and the scenario's deck-tilt predictor read
  on it at the contact times a commit chooses among
  (:mod:`~landing_env.anticipation.onboard_tilt_prediction`).
* From the ship, seconds ahead (0.5-8 s): the forecast of the helideck's motion made from the
  ship's HMS record (:mod:`~landing_env.anticipation.hms_forecast`), which the onboard
  look-ahead of ``timing-dqn-lookahead`` plays.

The predictors themselves are pure and live in :mod:`estimation.anticipation`.
"""

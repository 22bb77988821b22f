"""Training: the trainer (:mod:`~agents.training.trainer`), the randomised sampler, the
look-ahead's data and training, the onboard deck-tilt predictor's fit and the learning curve."""

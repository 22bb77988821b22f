"""Training: the trainer (:mod:`~agents.training.trainer`), tuning, the randomised sampler,
hindsight labels, the look-ahead's data and training, the deck predictor's fit and the
learning curve."""

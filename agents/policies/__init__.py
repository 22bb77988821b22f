"""Both tasks' policies and their one registry (:mod:`~agents.policies.registry`): the scripted
landings, the timing policies, the look-ahead, the oracles and the trained lander.  Imports
:mod:`agents.common` only, never training, evaluation or the command line."""

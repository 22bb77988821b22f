"""The layer beneath the roles: model cards (:mod:`~agents.common.cards`), the parallel runner
(:mod:`~agents.common.parallel`) and the user-error type (:mod:`~agents.common.user_input`).
It imports no role (policies, training, calibration, evaluation, io, cli)."""

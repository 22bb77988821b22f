"""Calibration: in simulation (:mod:`~agents.calibration.simulated`), from photos
(:mod:`~agents.calibration.photos`) and of the ToF sensor from a recording
(:mod:`~agents.calibration.tof`)."""

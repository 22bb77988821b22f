"""The papers' calibrations run in the simulator: chessboard intrinsics and ToF–camera pads.

:mod:`landing_env.calibration.intrinsics_sim` (CRHF Sec. 2.1–2.2) and
:mod:`landing_env.calibration.tof_camera_sim` (IHRCF Sec. 2.2, CRHF Sec. 2.3); the
``deck-landing calibrate`` command runs both (:mod:`agents.calibration.simulated`).
"""

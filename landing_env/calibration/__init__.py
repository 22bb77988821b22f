"""The papers' calibrations run in the simulator: chessboard intrinsics and ToF–camera pads.

:mod:`landing_env.calibration.intrinsics_sim` (CRHF Sec. 2.1–2.2) and
:mod:`landing_env.calibration.tof_camera_sim` (IHRCF Sec. 2.2, CRHF Sec. 2.3); the
``deck-landing calibrate`` command runs both (:mod:`agents.calibration.simulated`).
"""

#: what turns an environment config into a calibration rig: the deck still at home, the
#: drone on its own (no wind), no window and no EGL
STILL_RIG: dict[str, object] = {
    "motion.kind": "static",
    "motion.static.position_m": (0.0, 0.0, 0.0),
    "motion.static.attitude_deg": (0.0, 0.0, 0.0),
    "camera.use_egl": False,
    "simulation.gui": False,
    "wind.enabled": False,
}

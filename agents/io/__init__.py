"""Input and output off the simulator: bridges to autopilots (MAVLink) and recordings."""

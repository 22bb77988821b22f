"""Off the simulator: recorded data in and out, and bridges to autopilots.

* the plain-folder and ROS 2 (MCAP, rosbag2) readers and the ``deck-landing estimate`` command
  (``docs/howto/recorded-data.md``), and the simulator's MCAP recorder;
* ``deck-landing bridge``: the estimate to PX4 or ArduPilot as MAVLink ``LANDING_TARGET``,
  with TIMESYNC and the vehicle's pose from the autopilot (``docs/howto/mavlink.md``).

Needs the optional extra ``io`` (``pip install deck-landing[io]``: ``mcap``,
``mcap-ros2-support``, ``rosbags``, ``pymavlink``).
"""

"""Recorded data in and out: the plain-folder and ROS 2 (MCAP, rosbag2) readers, the
``deck-landing estimate`` command and the simulator's MCAP recorder.

Needs the optional extra ``io`` (``pip install deck-landing[io]``: ``mcap``,
``mcap-ros2-support``, ``rosbags``).  The formats, topics and frames are described in
``docs/howto/recorded-data.md``.
"""

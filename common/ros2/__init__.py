"""ROS 2 on the wire, for talking to ROS 2 nodes through Zenoh without ROS installed.

- :mod:`common.ros2.msgs`: the message types as CDR (pycdr2);
- :mod:`common.ros2.wire`: rmw_zenoh's keys, liveliness tokens and attachment (pure,
  pinned to the rmw_zenoh release named there);
- :mod:`common.ros2.types`: message types with their names and type hashes;
- :mod:`common.ros2.node`: ``Ros2Node``, a ROS 2 node over a ``zenoh.Session``.
"""

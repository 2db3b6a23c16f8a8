"""ROS 2 on the wire, for talking to ROS 2 nodes through Zenoh without ROS installed.

- :mod:`services.base.ros2.msgs`: the message types as CDR (pycdr2);
- :mod:`services.base.ros2.wire`: rmw_zenoh's keys, liveliness tokens, GIDs and attachment
  (pure; the rmw_zenoh_cpp releases it speaks with are named there: Jazzy 0.2.4 and
  later); topics only, no ROS 2 services or actions;
- :mod:`services.base.ros2.types`: message types with their names and type hashes;
- :mod:`services.base.ros2.node`: ``Ros2Node``, a ROS 2 node over a ``zenoh.Session``.
"""

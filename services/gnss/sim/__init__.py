"""The device simulators of this service (hardware-in-the-loop: each speaks its
device's own protocol on its own wire); none of this runs on the robot."""

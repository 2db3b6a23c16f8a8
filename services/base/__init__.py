"""The base service: the mobile base driver: velocity commands, wheel odometry, 2D lidar."""

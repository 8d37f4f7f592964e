"""The simulated Namo (MuJoCo) and its trajectory controllers, free of ROS."""

"""
The simulated Namo, free of ROS (``ros/sim_node.py`` puts it on ROS as ``namo_sim``).

- :mod:`.physics`: Namo in MuJoCo from the generated URDF: position actuators, stuck
  joints, self-contacts with the designed hand contact of two-handed gestures;
- :mod:`.trajectory`: a joint trajectory controller's rules (validation, sampling), as
  ros2_control's JointTrajectoryController applies them.
"""

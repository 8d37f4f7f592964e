"""
The simulated robot, free of ROS (``ros/sim_node.py`` puts it on ROS as ``namo_sim``).

- :mod:`.physics`: Namo in MuJoCo from the generated URDF, or a profile robot from its
  own: position actuators, stuck joints, self-contacts with the designed hand contact
  of two-handed gestures;
- :mod:`.profile_model`: a profile robot's URDF as MuJoCo takes it (no meshes, only
  the arm joints move) and its capsules, re-placed between its landmarks each step;
- :mod:`.structure_change`: changes the planner does not know (a tool, a bent link, an
  encoder offset, a link length), applied to the simulator's own copy of the URDF;
- :mod:`.tracker`: a fingertip tracker as a camera gives it (noise, latency, rate,
  dropouts; stamped at capture) and the true fingertips of the changed copy;
- :mod:`.trajectory`: a joint trajectory controller's rules (validation, sampling), as
  ros2_control's JointTrajectoryController applies them.
"""

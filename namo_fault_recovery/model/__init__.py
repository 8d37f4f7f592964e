"""
The robot and its gestures, free of ROS: what Namo is and what it should do.

- :mod:`.robot`: the arm model (DH table, joint names, limits, capsules, a tool) loaded
  from ``config/namo_robot.yaml``;
- :mod:`.kinematics`: forward kinematics and its Jacobian, batched over N configurations,
  and the arm's roll-pitch-roll flips (two joint readings of one pose);
- :mod:`.urdf_tree`: any robot's kinematic tree read from its URDF (yourdfpy), checked;
- :mod:`.rotations`: rotation matrices (elementary, about an axis, batched rotation vectors);
- :mod:`.chain`: a base-to-tip chain compiled from that tree: batched FK and Jacobians;
- :mod:`.robot_profile`: the recovery profile (arms, landmarks, roles of joints) over a URDF;
- :mod:`.profile_robot`: the engine's robot built from a profile (reduced chains);
- :mod:`.shared_joints`: the joints both arms hang from (a torso) as one rigid motion
  of the arms' base;
- :mod:`.structure`: a correction measured on the robot, compiled into the arm's chain;
- :mod:`.robot_capsules`: self-collision capsules fitted to a URDF's collision geometry;
- :mod:`.torso_field`: the torso's own shape as a signed distance field, where its
  capsule, capped by the resting arms, leaves it uncovered;
- :mod:`.profile_template`: a template profile guessed from a URDF's tree and names;
- :mod:`.capsules`: the capsule geometry of the arms and torso;
- :mod:`.self_contact`: capsule distances, the checked pairs, designed contact, and the
  load-time check that no reference pose goes into the robot's own body;
- :mod:`.gestures`: the reference gesture library (keyframes, weights, expansion stages);
- :mod:`.weights`: ``ScoreWeights``, the similarity components a gesture's score weighs;
- :mod:`.trajectory_csv`: dense recorded motions stored as CSV files;
- :mod:`.circle_design`: how the demo circle motion was designed;
- :mod:`.urdf`: Namo's URDF generated from the robot file (robot_state_publisher, RViz,
  the simulator);
- :mod:`.yaml_checks`: the small validators that name the file and key of a bad value.
"""

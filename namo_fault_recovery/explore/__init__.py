"""
Exploration on the robot: adapt to a structure change the model does not know.

The second source paper adapts designed motions to a changed structure without model
identification: it measures where the end effector really is, explores trial motions
at a few typical points, spreads the corrections by Kriging and expands the DOF in
stages.  This subpackage does it with measured fingertips, ROS-free and for any robot
whose arm is a :class:`~namo_fault_recovery.model.chain.KinematicChain`:

- :mod:`.trial`: the trial-robot protocol (one arm: command, settle, measure), the
  safety checks every trial pose passes, the stoppable counted session, and a
  kinematic trial robot for tests and quick runs;
- :mod:`.safety`: the model's self-collision clearance (Namo's capsules) for the checks;
- :mod:`.task`: what one exploration is asked (typical points, targets, layouts) and
  what it found;
- :mod:`.annealing`: the paper's explorer, simulated annealing on the measured error;
- :mod:`.corrections`: structural corrections of the nominal chain (tip offset, joint
  offsets, bends) fitted to all measurements and chosen by BIC, and the batched
  inverse kinematics on a corrected model;
- :mod:`.secant`: ours, Gauss-Newton steps on the measured error with the corrected
  model's Jacobian and Broyden updates per point;
- :mod:`.motion`: one motion explored and spread to every point by Kriging, the
  ``explored`` result.

It never imports the simulator, ROS, the runtime or the benchmarks: a trial robot is
handed in (the benchmark's runs the simulator's physics).
"""

"""
Playing the gesture library on the robot, free of ROS.

- :mod:`.timing`: from the measured pose and a gesture's keyframes to a smooth,
  speed-limited trajectory that holds every locked joint at its lock angle;
- :mod:`.clearance`: a played path that presses the body no deeper than its keyframes
  do: where the spline between them would, one via pose bends it out of the contact;
- :mod:`.monitor`: tracking of the commands on the measured joint states: a stuck
  joint is a fault, the last point reached within tolerance is the end of the motion;
- :mod:`.deviation`: noticing a structure change: the tracked fingertip, at its capture
  stamp, off both the designed path and the model's fingertip of the measured joints;
- :mod:`.tracking`: the model of a controller's tracking the monitor compares with
  (delay and first-order lag), and its fit to healthy plays;
- :mod:`.blend`: the rest of a motion from one of its instants, a time-optimal stop,
  the same phase in a reconfigured plan, and a blend from the measured state onto a
  trajectory within the velocity and acceleration limits;
- :mod:`.carry`: one play that carries on through a stuck joint: hold it and stop,
  wait for the reconfigured library, blend onto it at that phase, go on;
- :mod:`.book`: library versions and lock angles known between plays;
- :mod:`.export`: the library as a play_motion2 motions file;
- :mod:`.plot`: the figure of one play (commanded and measured angles).

The ``gesture_player`` node (:mod:`..ros.player_node`) only moves messages in and out.
"""

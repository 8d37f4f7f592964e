"""
The node's runtime: the recovery node's logic, free of ROS (plain threads and processes).

``ros/node.py`` wires these parts to the topics, services and parameters; each part has
fast unit tests that need no DDS.

- :mod:`.run_book`: the run bookkeeping (requested, running, published, who waits);
- :mod:`.fault_intake`: fault reports persisted before they are acknowledged;
- :mod:`.inputs`: validation of fault reports and joint states (no ROS types);
- :mod:`.dispatcher`: the thread that runs the newest request and publishes it;
- :mod:`.robot_source`: the node's robot from its parameters: the DH ``robot_file``, or
  any robot's ``robot_profile`` and URDF (``robot_description``), with its library;
- :mod:`.engine_process`: the engine in its own process (no shared interpreter lock),
  which also refines a published library in the background;
- :mod:`.contingency_keeper`: the contingency table looked up before a live run, built
  by a low-priority background process and kept in ``state_dir``;
- :mod:`.answer_pacer`: service answers released a few at a time;
- :mod:`.latest_worker`: one delayed thread for the newest item (the RViz markers);
- :mod:`.log_throttle`: at most one log line per kind of rejected input and second, with
  the count of those held back;
- :mod:`.demand_tick`: a periodic tick that stops itself while it has no work;
- :mod:`.realtime`: ``SCHED_FIFO`` for the node's own threads (``thread_priority``),
  the normal scheduler for its child processes, and the engine's nice value
  (``engine_nice``);
- :mod:`.persistence`: the state file in the order the run book needs, off the hot paths;
- :mod:`.restore`: the checks before publishing, and the restore decision;
- :mod:`.state_store`: the persisted fault set and library (no ROS types);
- :mod:`.diagnostic_keys`: the ``/diagnostics`` names and keys shared by writer and readers;
- :mod:`.trial_robot`: the gesture player's trial robot for exploration (one arm's
  command, settle, tracker readings), fed by its callbacks, waited on by its worker;
- :mod:`.explored_store`: the player's explored motions and their fitted corrections
  on disk (``explore_state_file``), so that a restart serves them again;
- :mod:`.private_node`: the node processes that the demos, the node benchmarks and the
  tests start (the executables' commands, a private domain, one way to stop a process).
- :mod:`.explored_version`: a library version explored on the robot, scored as measured;
"""

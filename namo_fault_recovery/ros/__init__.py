"""
The ROS 2 side: the modules that import rclpy or a message package, and only those.

The node (its ROS-free parts, the run book, dispatcher, engine process and the rest, are
the node's runtime, ``runtime/``):

- :mod:`.recovery_node`: ``main()``, light, with the signal handling of start-up;
- :mod:`.spin`: ``run_node``, the one ``main()`` body of the three nodes, and
  ``spin_until_shutdown``, their spin loop that a lost shutdown wake-up cannot hang;
- :mod:`.node`: ``RecoveryNode``, which wires the interfaces to the runtime's parts;
- :mod:`.parameters`: the parameter table, its validator and the node's settings;
- :mod:`.description_wait`: the URDF from the ``robot_description`` topic, waited for
  (and said on ``/diagnostics``) when the robot's profile names none;
- :mod:`.input_monitor`: the latest joint state, measured angles and rejected inputs;
- :mod:`.topic_listener`: one subscription taken on a helper node, in a thread and on a
  wait set of its own, without an executor: the node's ``/joint_states`` (a 500 Hz
  stream does not wake the node's executor) and ``/actuator_fault``, and every client's
  ``/gesture_library``;
- :mod:`.diagnostics`: ``/diagnostics`` built from a snapshot;
- :mod:`.messages`: results to and from ROS messages, and the RViz markers.

Clients of a running node (the benchmarks themselves are in ``benchmarks/``):

- :mod:`.client`: the typed rclpy client of a running node, used by the ROS commands,
  the benchmarks and the test harnesses (the one ``/gesture_library`` subscription);
- :mod:`.player_client`: the client of ``gesture_player`` (its play services, and what
  the arms were commanded);
- :mod:`.joint_state_stream`: a ``/joint_states`` stream as a robot's drivers publish
  it, in a thread or a child process;
- :mod:`.spun_node`: an rclpy node in a context of its own, spun by a background thread
  (the clients and the tests each use one), and ``wait_until`` for what it records.

The gesture player and the simulated robot:

- :mod:`.player_node`: ``gesture_player``, which plays the library on the arm controllers
  and reports a joint that stays off its command;
- :mod:`.structure_watch`: the player's watch for a structure change (the tracked
  fingertip off the designed path), on ``/diagnostics`` and ``/structure_change``;
- :mod:`.exploration`: the player's exploration on the robot (``~/explore``, a worker
  thread, progress on ``/diagnostics``, the explored motions it then plays);
- :mod:`.sim_node`: ``namo_sim``, Namo in MuJoCo behind two joint trajectory controllers,
  with a structure the planner does not know and a fingertip tracker (the physics, the
  controller rules, the changes and the tracker are in ``sim/``, free of ROS);
- :mod:`.fingertip_topics`: the fingertip tracker's topics, both ends (names, QoS,
  ``PointStamped`` in metres to and from mm).
- :mod:`.explored_intake`: the node adopts the player's measured corrections and motions;
"""

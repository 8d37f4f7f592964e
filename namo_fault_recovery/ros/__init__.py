"""
The ROS 2 side: the node and everything that touches rclpy or a message package.

The node and its parts (the parts are free of DDS, with fast unit tests):

- :mod:`.recovery_node`: ``main()``, light, with the signal handling of start-up;
- :mod:`.node`: ``RecoveryNode``, which wires the interfaces to the parts below;
- :mod:`.parameters`: the parameter table, its validator and the node's settings;
- :mod:`.run_book`: the run bookkeeping (requested, running, published, who waits);
- :mod:`.fault_intake`: fault reports persisted before they are acknowledged;
- :mod:`.input_monitor`: the latest joint state, measured angles and rejected inputs;
- :mod:`.inputs`: validation of fault reports and joint states (no ROS types);
- :mod:`.dispatcher`: the thread that runs the newest request and publishes it;
- :mod:`.engine_process`: the engine in its own process (no shared interpreter lock),
  which also refines a published library in the background;
- :mod:`.contingency_keeper`: the contingency table looked up before a live run, built
  by a low-priority background process and kept in ``state_dir``;
- :mod:`.answer_pacer`: service answers released a few at a time;
- :mod:`.latest_worker`: one delayed thread for the newest item (the RViz markers);
- :mod:`.persistence`: the state file in the order the run book needs, off the hot paths;
- :mod:`.restore`: the checks before publishing, and the restore decision;
- :mod:`.state_store`: the persisted fault set and library (no ROS types);
- :mod:`.diagnostics`: ``/diagnostics`` built from a snapshot;
- :mod:`.diagnostic_keys`: the ``/diagnostics`` names and keys shared by writer and readers;
- :mod:`.messages`: results to and from ROS messages, and the RViz markers.

Clients of a running node (the benchmarks themselves are in ``benchmarks/``):

- :mod:`.client`: the typed rclpy client of a running node, used by the ROS commands,
  the benchmarks and the test harnesses (the one ``/gesture_library`` subscription);
- :mod:`.player_client`: the client of ``gesture_player`` (its play services, and what
  the arms were commanded);
- :mod:`.joint_state_stream`: a ``/joint_states`` stream as a robot's drivers publish
  it, in a thread or a child process;
- :mod:`.spin`: ``spin_until_shutdown``, the nodes' spin loop that a lost shutdown
  wake-up cannot hang;
- :mod:`.spun_node`: an rclpy node in a context of its own, spun by a background thread
  (the clients and the tests each use one), and ``wait_until`` for what it records.

The gesture player and the simulated robot:

- :mod:`.player_node`: ``gesture_player``, which plays the library on the arm controllers
  and reports a joint that stays off its command;
- :mod:`.sim_node`: ``namo_sim``, Namo in MuJoCo behind two joint trajectory controllers
  (the physics and the controller rules are in ``sim/``, free of ROS).
"""

"""
The ``namo-recovery`` command line, one module per command group.

- :mod:`.main`: the parser and the offline commands (``show``, ``score``, ``solve``);
- :mod:`.bench`: ``bench paper | optimum | speed | deadline`` and ``plot``;
- :mod:`.beyond`: the benchmarks of the extensions beyond the paper;
- :mod:`.node_commands`: ``fault``, ``clear``, ``reconfigure``, ``library`` against a
  running node (rclpy imported lazily, as in every ROS command);
- :mod:`.demo`: ``demo``, a private node driven end to end;
- :mod:`.latency_bench`: ``bench latency``;
- :mod:`.product_bench`: ``bench product``, the served problem (offline parts in
  ``benchmarks/product.py``, the DDS parts here);
- :mod:`.stream_bench_command`: ``bench stream`` (the measurement is in ``ros/``);
- :mod:`.export`: ``export --format play_motion2`` (from the running node or a solve);
- :mod:`.player_commands`: ``play``, ``demo-play`` and ``bench detection``, around
  ``gesture_player``;
- :mod:`.urdf`: ``urdf``, Namo's URDF from the robot file;
- :mod:`.precompute`: ``precompute``, the contingency table built offline;
- :mod:`.settings_command`: ``settings``, the parameter file and tables written from the
  settings' declaration;
- :mod:`.ros_common`: what the ROS commands share (``--namespace``, errors, tables);
- :mod:`.private_node`: the node process that ``demo`` and ``bench latency`` start;
- :mod:`.common`: argument parsing shared by the groups (faults, the setting options);
- :mod:`.__main__`: ``python -m namo_fault_recovery.cli``.
"""

"""
The ``namo-recovery`` command line, one module per command group.

The commands parse their options and call the package: the benchmarks in
``benchmarks/``, the engine in ``recovery/``, the nodes through ``ros/client.py`` and
``ros/player_client.py`` (imported when a ROS command runs; no rclpy here).

- :mod:`.main`: the parser and the offline commands (``show``, ``score``, ``solve``);
- :mod:`.bench`: ``bench paper | optimum | speed | deadline`` and ``plot``;
- :mod:`.beyond`: the benchmarks of the extensions beyond the paper;
- :mod:`.notice_bench`: ``bench notice``, noticing a structure change;
- :mod:`.node_bench`: ``bench latency | stream | product | callers``, the benchmarks of
  a node;
- :mod:`.node_commands`: ``fault``, ``clear``, ``reconfigure``, ``library`` against a
  running node;
- :mod:`.demo`: ``demo``, a private node driven end to end;
- :mod:`.export`: ``export --format play_motion2`` (from the running node or a solve);
- :mod:`.player_commands`: ``play``, ``demo-play``, ``bench detection`` and ``bench
  carry-on``, around ``gesture_player``;
- :mod:`.urdf`: ``urdf``, Namo's URDF from the robot file;
- :mod:`.retarget_command`: ``retarget``, a gesture library moved to another robot's
  profile;
- :mod:`.profile_command`: ``profile``, a template recovery profile guessed from a
  URDF;
- :mod:`.precompute`: ``precompute``, the contingency table built offline;
- :mod:`.settings_command`: ``settings``, the parameter file and tables written from the
  settings' declaration;
- :mod:`.ros_common`: what the ROS commands share (``--namespace``, errors, tables);
- :mod:`.common`: argument parsing shared by the groups (faults, the setting options);
- :mod:`.__main__`: ``python -m namo_fault_recovery.cli``.
"""

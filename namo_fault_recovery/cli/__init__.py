"""
The ``namo-recovery`` command line, one module per command group.

- :mod:`.main`: the parser and the offline commands (``show``, ``score``, ``solve``);
- :mod:`.bench`: ``bench paper | optimum | speed | deadline`` and ``plot``;
- :mod:`.beyond`: the benchmarks of the extensions beyond the paper;
- :mod:`.ros_commands`: the commands that talk to a running node (rclpy imported lazily);
- :mod:`.common`: argument parsing shared by the groups.
"""

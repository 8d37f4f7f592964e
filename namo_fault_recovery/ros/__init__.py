"""
The ROS 2 side: the node and everything that touches rclpy or a message package.

- :mod:`.recovery_node`: ``main()`` and the node that wires the interfaces;
- :mod:`.client`: the typed rclpy client of a running node, used by the ROS commands;
- :mod:`.diagnostic_keys`: the ``/diagnostics`` names and keys shared by writer and readers;
- :mod:`.messages`: results to and from ROS messages, and the RViz markers;
- :mod:`.inputs`: validation of fault reports and joint states (no ROS types);
- :mod:`.state_store`: the persisted fault set and library (no ROS types).
"""

"""
The node's runtime: what runs beside the ROS interfaces, free of ROS.

- :mod:`.private_node`: the node processes that the demos, the node benchmarks and the
  tests start (the executables' commands, a private domain, one way to stop a process).
"""

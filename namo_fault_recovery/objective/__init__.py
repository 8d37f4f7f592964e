"""
What a good reconfiguration is, free of ROS.

- :mod:`.score`: the paper's similarity score (elbow, wrist, fingertip, palm, hand gap),
  with its batched gradient;
- :mod:`.collision`: the capsule self-collision model and its penalty.
"""

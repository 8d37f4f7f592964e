"""
What a good reconfiguration is, free of ROS.

- :mod:`.score`: the paper's similarity score (elbow, wrist, fingertip, palm, hand gap),
  with its batched gradient (its weights, ``ScoreWeights``, are part of a gesture and
  live in ``model/weights.py``; ``score`` re-exports them);
- :mod:`.collision`: the capsule self-collision model and its penalty;
- :mod:`.mesh_clearance`: the same pairs measured on a profile robot's URDF collision
  meshes (Pinocchio and coal, the ``robots`` extra), to cross-check the capsules.
"""

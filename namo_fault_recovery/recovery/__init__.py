"""
From a fault set to an adapted gesture library, free of ROS.

- :mod:`.engine`: the one entry point, ``recover(robot, library, faults, settings)``;
- :mod:`.settings`: every setting declared once (name, type, default, range or choices,
  unit, doc, flags) and :class:`~.settings.RecoverySettings`, named as the node's
  parameters, with its one validator;
- :mod:`.result`: the one result type, ``LibraryResult`` / ``GestureResult``, that the
  keyframe search and the motion adaptation build and the node, the state file, the
  messages, ``solve`` and the benchmarks read;
- :mod:`.contingency`: the contingency table, best libraries precomputed offline per
  likely fault set, keyed by resolved lock angles (``namo-recovery precompute``);
- :mod:`.refine`: anytime refinement, ever better libraries after the deadline result;
- :mod:`.locks`: lock strategies (``average``, ``measured``, ``optimal``) and lock angles;
- :mod:`.keyframes`: the batched pose problems of every keyframe, solved within one
  deadline (the first paper's method, with stage 2 and the collision term);
- :mod:`.lean`: the last stage of the staged DOF expansion, the torso's lean, on a
  robot whose arms hang from shared joints (``expand_shared``);
- :mod:`.seeding`: the keyframe search's starting sources, random draws taken a few
  damped least-squares steps towards the landmarks, and the design through each of the
  arm's flips (so the colony starts in good basins);
- :mod:`.twins`: each gesture's solved keyframes on the kinematic twins whose path from
  rest presses the body least, then nearest its design (the same landmarks and score;
  the far twin swings the arm half a turn, maybe through the body);
- :mod:`.constrained`: one pose solved with the capsules' clearances as hard constraints
  (SLSQP), which reaches the best clear pose where a penalty descent stays out of its
  basin (the keyframe search's first step for a colliding pose);
- :mod:`.least_squares`: reweighted Gauss-Newton on the score's terms: those steps, and
  the search's last local step, which ends on the score's kinks where the polish crawls;
- :mod:`.motion`: whole-motion adaptation (the second paper: typical points and Kriging,
  point by point, or Kriging then the whole trajectory at once);
- :mod:`.figures`: an adapted motion's figures as a ``GestureResult`` (scores, fingertip
  error, joint jumps, collisions) and the locked-design fallback of a cut-short run;
- :mod:`.trajectory_opt`: whole-trajectory optimisation of a dense motion (every point
  at once, batched analytic gradients, a smoothness term; ``auto``'s pass after Kriging);
- :mod:`.pacing`: the joints' velocity limits between keyframes as constraints of the
  search (step limits from the player's spline, feasible repairs, per-keyframe boxes);
- :mod:`.vq`: vector quantisation that picks a motion's typical points;
- :mod:`.retarget`: a gesture library moved to another robot (scaled landmarks);
- :mod:`.kriging`: the variogram fit and ordinary Kriging;
- :mod:`.budget`: how the caller's one deadline clock is shared out (reserves, shares).

Every function below :func:`~.engine.recover` takes the ``RecoverySettings`` unchanged
(or the one setting it needs, under its name) and the caller's one ``Clock``.
"""

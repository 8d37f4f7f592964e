"""
Every benchmark: the paper's comparison, the optimum, speed, deadlines, the node's.

These are commands, not timed tests (``namo-recovery bench ...``; the command line only
parses the options and calls them).  Each module has one ``run_*`` function that
returns a plain dict (written as JSON) and prints its figures:

- :mod:`.paper`: GA, BFOA and ABC (paper presets) and our default ABC over the 28
  (gesture, failed right-arm joint) cases, as the paper's Tables 3-6;
- :mod:`.optimum`: the best-known optimum of every case by dense multistart local
  search, stored in ``config/best_known_optima.yaml``, and every algorithm's gap to it;
- :mod:`.speed`: whole-library time and quality of our default against the paper ABC;
- :mod:`.deadline`: the worst deadline overrun, idle and with a CPU burner;
- :mod:`.beyond`, :mod:`.motion`: the extensions beyond the paper, whole motions;
- :mod:`.explore`: adaptation to a change the model does not know, by trials on the
  simulated robot: the paper's SA, ours, every point, the IK floor
  (``bench explore``);
- :mod:`.lock_compare`: ``average`` against ``optimal`` lock angles, every single fault;
- :mod:`.detection`: stuck-joint detection and recovery on the simulator's physics
  (``bench detection``);
- :mod:`.detection_suite`: the detector over every gesture of both libraries, idle and
  busy: latency, false alarms, score gap, playability (``bench detection-suite``);
- :mod:`.carry_on`: a joint stuck mid-gesture, the time until the arm is back on the
  reconfigured trajectory, on the simulator's physics (``bench carry-on``);
- :mod:`.product`: the served problem (packaged library, node settings): best-known
  optima, quality at the deadline, the contingency table, free of ROS;
- :mod:`.product_node`: ``bench product`` whole: those parts, and the latency and
  refinement curve of private nodes over DDS;
- :mod:`.latency`: fault -> library latency of a running or private node
  (``bench latency``);
- :mod:`.stream`: the node's deadline and latency while ``/joint_states`` streams and a
  CPU burner runs (``bench stream``);
- :mod:`.callers`: crowds of default-QoS service callers, every call answered?
  (``bench callers``);
- :mod:`.idle`: a private node's idle CPU (its process tree, table off and on) and
  clean SIGTERM stops of ``recovery_node`` and ``namo_sim`` (``bench idle``);
- :mod:`.robots`: every single fault x the four gestures on Talos or TIAGo++ from their
  profiles, against per-robot best-known optima (``bench robots``);
- :mod:`.meshes`: what the capsules pass as clear, measured on a profile robot's URDF
  collision meshes, every published keyframe of every single fault (``bench meshes``);
- :mod:`.notice`: ``bench notice``: time to notice a hidden structure change and false
  alarms, on the simulator's clock;
- :mod:`.fk`: the URDF-compiled chains' FK against the DH FK on Namo (``bench fk``);
- :mod:`.playability`: the libraries the player would have to stretch (joint velocity
  limits), every single fault, at a fixed small budget and at the deadline
  (``bench playability``);
- :mod:`.common`: models, cases, statistics and output files shared by the above;
- :mod:`.paper_data`: the paper's published tables, to print beside ours;
- :mod:`.plotting`: the figures (matplotlib, optional), and the ``plot`` command's run.

The node benchmarks reach ROS only through ``ros/`` (:class:`~namo_fault_recovery.ros.
client.RecoveryClient`, :class:`~namo_fault_recovery.ros.joint_state_stream.
StreamProcess`) and start nodes with :mod:`namo_fault_recovery.runtime.private_node`.

Every library they need comes from the engine's entry point, ``recover()``, through
:func:`.common.run_recover` with explicit settings (:data:`.common.PAPER_SETTINGS` for
the paper's problem), and they read its ``LibraryResult``.  Only the paper's per-case
runs (:func:`.common.run_gesture`) and the optimum search solve the keyframe problem
directly, as the paper reports the optimiser's own best.
"""

from .optimum import BEST_KNOWN_FILE, load_best_known

__all__ = ['BEST_KNOWN_FILE', 'load_best_known']

"""
Benchmarks that print figures: the paper's comparison, the optimum, speed, deadlines.

These are commands, not timed tests (``namo-recovery bench ...``).  Each module has one
``run_*`` function that returns a plain dict (written as JSON) and prints its figures:

- :mod:`.paper`: GA, BFOA and ABC (paper presets) and our default ABC over the 28
  (gesture, failed right-arm joint) cases, as the paper's Tables 3-6;
- :mod:`.optimum`: the best-known optimum of every case by dense multistart local
  search, stored in ``config/best_known_optima.yaml``, and every algorithm's gap to it;
- :mod:`.speed`: whole-library time and quality of our default against the paper ABC;
- :mod:`.deadline`: the worst deadline overrun, idle and with a CPU burner.
"""

from .optimum import BEST_KNOWN_FILE, load_best_known

__all__ = ['BEST_KNOWN_FILE', 'load_best_known']

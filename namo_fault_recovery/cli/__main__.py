"""Run the ``namo-recovery`` command line: ``python -m namo_fault_recovery.cli``."""

import sys

from .main import main

sys.exit(main())

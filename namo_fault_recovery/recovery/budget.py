"""
How the one deadline of a reconfiguration is shared out: every reserve and share.

The caller (the node, :func:`.engine.recover`) owns a single
:class:`~namo_fault_recovery.optimize.base.Clock`.  Each stage derives its own budget
from that clock with :meth:`~namo_fault_recovery.optimize.base.Clock.child`, keeping
back the reserves below for the work that follows it, so that the figures live here
and nowhere else, and no stage can run past the caller's deadline.

Reserves are seconds kept back (each at most half of the time left, see ``child``);
shares are fractions of the time left when the stage starts.
"""

# Reserves, in seconds, for the work after a search.
PUBLISH_RESERVE = 0.010   # recover() builds the result; the node converts and publishes it
FINISH_RESERVE = 0.030    # adapt_library: Kriging, the figures, the collision check of points
ENGINE_RESERVE = 0.015    # reconfigure_library: scoring and the collision check of keyframes

# Shares of the time left.
VQ_SHARE = 0.2            # typical points (vector quantisation) of the whole library
TYPICAL_SHARE = 0.9       # typical points in ``auto`` (the whole-trajectory pass: the rest)
STAGE1_SHARE = 0.6        # stage 1 (and each expansion stage) when a later stage may follow

"""Head-camera hand-eye calibration on a rig: pose planning, collection from a ``Robot``, solving and checks.

The solvers themselves live in :mod:`calib` (which must not depend on ``pilworld``); this package adds
what needs the rig: kinematics (planning reachable board poses, FK of the measured joints), the
``Robot`` contract (collection), recordings on disk, and the simulated rig's ground truth.
"""

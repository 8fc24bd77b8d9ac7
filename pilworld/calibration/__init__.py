"""Hand-eye calibration on a rig, by step, for the head camera (eye-to-hand) and the wrist cameras (eye-in-hand).

The solvers themselves live in :mod:`calib` (which must not depend on ``pilworld``); this package adds
what needs the rig. Each step is written once, with the camera mount
(:class:`calib.handeye_mount.CameraMount`) as its parameter:

* **plan** reachable, diverse poses (:mod:`.plan`, with :mod:`.plan_sampling`, :mod:`.plan_filters`,
  :mod:`.plan_settings`);
* **collect** the views through the ``Robot`` contract (:mod:`.collect`; on a hardware rig
  :mod:`.rig_collection`), kept as recordings on disk (:mod:`.recording`);
* **solve** (:mod:`.solve`; the head camera with both arms: :mod:`.solve_arms`);
* **check** on held-out views (:mod:`.check`);
* the **simulated run**, where the answer is known (:mod:`.sim_handeye`, :mod:`.sim_truth`).

:mod:`.run_handeye` and :mod:`.run_check` are what ``pilworld calibrate handeye|check`` run
(docs/calibration.md).
"""

"""The mocked backend: a MuJoCo dual-arm rig with three cameras and the paper's three tasks.

``SimRobot`` (``hw_drivers.sim.robot``) implements the ``Robot`` contract; the scene is generated from
the rig config (``hw_drivers.sim.scene``); tasks live in ``hw_drivers.sim.tasks``. Importing the robot
selects headless OpenGL (``MUJOCO_GL=egl`` unless set) before MuJoCo loads.
"""

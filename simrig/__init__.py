"""The simulated rig: a MuJoCo dual-arm rig with three cameras, built from a rig config and a task file.

``SimRobot`` (``simrig.robot``) implements ``hw_drivers.robot.Robot``; the scene is generated from the
rig config (``simrig.scene``) and the task file (``simrig.tasks``: the loader, the predicates and the
packaged task files). Importing the robot selects headless OpenGL (``MUJOCO_GL=egl`` unless set)
before MuJoCo loads. It is a backend, not a driver: ``hw_drivers.fakes`` builds its protocol-level fake
devices on it.
"""

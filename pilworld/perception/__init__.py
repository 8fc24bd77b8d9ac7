"""Image code shared by the scripted policies, the judges and the world model: one home for perception.

* :mod:`.colour` — colour-blob perception from the head camera, for the scripted (observation-only) stand-in
  policies: they must see the scene the way evaluated policies do, not read object poses from the simulator;
* :mod:`.silhouette` — silhouettes of boxes and bowls and their render-and-compare pose fitting;
* :mod:`.views` — the camera models of a frame (the head camera, the wrist cameras placed by forward
  kinematics), pixel labels by colour, and the "held between the fingertips" test.

Nothing here knows a task: callers pass the shapes and colours they look for.
"""

from pilworld.perception.colour import Blob, ColourClass, Detection, largest_blob, locate_on_plane, segment

__all__ = ["Blob", "ColourClass", "Detection", "largest_blob", "locate_on_plane", "segment"]

"""Perception from the head-camera image alone, for scripted (observation-only) policies.

Scripted baselines must see the scene the way the evaluated policies do -- through ``cam_high`` -- rather
than read object poses from the simulator; this package turns images into rig-frame object positions.
"""

from pilworld.perception.colour import Blob, ColourClass, Detection, largest_blob, locate_on_plane, segment

__all__ = ["Blob", "ColourClass", "Detection", "largest_blob", "locate_on_plane", "segment"]

"""World model v2 (docs/world_model.md, 'World model v2'): a small network that composites what geometry already knows.

The robot is rendered from its own model (Γ⁺), the static scene is reprojected from the current frame,
and whatever a gripper holds is carried along with it by a rigid warp (:mod:`.layers`). A small
U-Net (:mod:`.net`) only chooses, per pixel, between these sharp candidate layers and a generated fill,
paints the robot's appearance from its render, and predicts the measured gripper opening (the state a
gripper resting on an object reports). See docs/world_model.md, "World model v2".
"""

"""The paper's three tasks as code knows them (objects, slots, goals), read from their task files.

Kept apart from everything that must learn from data: only the hand-written reference judge of the paper's
tasks (``pilworld.judges.vision_success``) and world model v2's tracked objects
(``pilworld.world_model.composite.objects``) read it, as the layering test's named exceptions.
"""

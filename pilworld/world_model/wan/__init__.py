"""The Wan2.1 world-model backend (:mod:`.backend`; extra ``pilworld[wan]``, docs/world_model.md, "Wan2.1 backend").

Loaded like any other world-model folder (:func:`pilworld.world_model.loader.load_world_model`), so
``--world-model WAN_DIR`` works on ``paired run`` and ``imagine``.
"""

"""Policies: anything with ``infer(observation, instruction) -> float32[H_π, 14]``."""

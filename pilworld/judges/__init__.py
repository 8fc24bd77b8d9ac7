"""Judges: the simulator checker, the image-only success judge, the hallucination detector, people."""

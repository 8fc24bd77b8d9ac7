"""Imagined-only runs from stored starts (``pilworld imagine``): :mod:`pilworld.imagine.runner`.

It sits above :mod:`pilworld.paired`: the imagined branch itself (:mod:`pilworld.paired.imagined_branch`)
and the run settings and model loading are the paired run's, so that the same start, checkpoint, seed and
model give the same episode in both.
"""

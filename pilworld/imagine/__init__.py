"""Imagined-only runs from stored starts (``pilworld imagine``): :mod:`pilworld.imagine.runner`.

Kept import-free: the paired runner imports :mod:`pilworld.imagine.branch`, and the runner imports it.
"""

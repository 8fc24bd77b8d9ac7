"""PiL-World: paired real/imagined closed-loop evaluation of VLA policies."""

__version__ = "0.1.0"

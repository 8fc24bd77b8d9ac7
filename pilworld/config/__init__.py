"""Validated YAML configs (``configs/``): every loader error names the file and the field."""

from pilworld.config.loader import ConfigError, load_yaml_model
from pilworld.config.rig import RigConfig

__all__ = ["ConfigError", "RigConfig", "load_yaml_model"]

"""Γ: action chunks → head-view control videos (markers sized by gripper opening, fading traces)."""

from pilworld.control_video.gamma import ControlGeometry, ControlVideo
from pilworld.control_video.style import ControlVideoStyle

__all__ = ["ControlGeometry", "ControlVideo", "ControlVideoStyle"]

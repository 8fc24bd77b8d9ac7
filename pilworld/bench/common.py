"""What every benchmark reports about the machine it ran on, so figures can be compared honestly."""

from __future__ import annotations

import os
import platform
import sys
from typing import Any

import numpy as np


def machine_info() -> dict[str, Any]:
    return {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "platform": platform.platform(terse=True),
        "machine": platform.machine(),
        "cpus": os.cpu_count(),
        "argv": sys.argv[1:],
    }

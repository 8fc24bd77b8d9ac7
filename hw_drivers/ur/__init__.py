"""Universal Robots arms over RTDE (``ur_rtde``), each in its own process."""

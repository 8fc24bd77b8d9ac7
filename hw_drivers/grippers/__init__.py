"""Grippers behind one contract: Dynamixel servos (dynamixel_sdk) and the Robotiq 2F-85 (Modbus RTU)."""

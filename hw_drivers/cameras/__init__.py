"""Cameras behind one contract: OpenCV ``VideoCapture`` on device indices and stream URLs."""

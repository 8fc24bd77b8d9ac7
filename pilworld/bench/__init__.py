"""Benchmarks behind ``pilworld bench <name>``: each returns a JSON-ready dict of measured figures."""

"""Robot hardware drivers behind one Robot contract (arms, grippers, cameras) and the simulated backend."""

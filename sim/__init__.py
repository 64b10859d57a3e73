"""Simulated Duffing rig: physics, table sweeps and accelerometers (ground truth for tests and demo)."""

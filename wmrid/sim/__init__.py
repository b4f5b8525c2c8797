"""Simulators: the reduced closed-loop prototype and the MuJoCo multibody prototype."""

"""Experiment design: the drive that identifies a robot (``wmrid plan``), its predicted precision, its limits."""

"""Lowest layer: errors and exit codes, the memory budget, interrupts, atomic outputs, the wheel-log types."""

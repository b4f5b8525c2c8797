"""Lowest layer, the domain's own types: errors and exit codes, the settings' choices, the optional extras, the
wheel-log types."""

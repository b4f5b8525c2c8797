"""Change detection against an identified model."""

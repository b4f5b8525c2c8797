"""Identification methods on logs in memory or streamed: the observer and its rivals, their uncertainty."""

"""Presentation: terminal tables, JSON, reports and figures."""

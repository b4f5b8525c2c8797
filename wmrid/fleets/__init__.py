"""A fleet of robots: its manifest and results table, identifying every log on Dask (the worker and the run), and the
fleet review (change tests over each robot's history, the figures, the report pages)."""

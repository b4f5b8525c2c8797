"""``wmrid export``: an identified robot written where it is used -- a simulator's model (MJCF, URDF) or a controller's
(YAML, a Python function).  Layer: beside :mod:`wmrid.reporting` (it reads results, the model and the simulator's
MJCF builder; the API and CLI call it)."""

"""wmrid: identify the dynamic parameters of differential-drive wheeled mobile robots from their logs."""

__version__ = "0.1.0"

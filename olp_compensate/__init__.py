"""olp-compensate: calibrate industrial robots and correct their offline-written programs."""

__version__ = "0.1.0"

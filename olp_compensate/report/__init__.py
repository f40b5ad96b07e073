"""Figures and HTML reports of calibrations and compensations (matplotlib, written files
only)."""

"""Calibration reports: HTML page and PNG figures (matplotlib, Agg)."""

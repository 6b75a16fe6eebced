"""Calibration runs around the kernels of ``omnijax.calibration``: observation files, checks, outputs, plots."""

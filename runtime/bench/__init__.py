"""Benchmark plumbing: one-core pinning, timing statistics, the detector against OpenCV's MOG2."""

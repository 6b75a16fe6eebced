"""The real-time room: frame sources and capture, the tracker, target choice, the loop, overlays, faults."""

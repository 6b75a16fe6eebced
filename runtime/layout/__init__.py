"""Figures of the layout search (``omnijax optimise``)."""

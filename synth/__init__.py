"""Synthetic controlled-change indoor scenes: layouts, rearrangement, lighting, rendering."""

__version__ = "0.1.0"

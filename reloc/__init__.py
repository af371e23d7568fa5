"""VideoReloc: video relocalization against a kilobyte-scale map of class-labelled boxes."""

__version__ = "0.1.0"

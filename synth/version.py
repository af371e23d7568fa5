"""The toolkit's version (pyproject.toml's, which a test keeps equal), importable without the API."""

__version__ = "0.1.0"

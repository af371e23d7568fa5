"""The back-end (paper Sec. III-F): tracking, run-level decision, clip-rigid pose graph, and ``reloc run``."""

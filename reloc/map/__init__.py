"""The map (paper Sec. III-B): the stored box map and its construction from a mapping tour."""

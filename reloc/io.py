"""reloc's outputs are written with synth's atomic writers (one implementation, ``synth.atomic``)."""

from synth.atomic import save_npz_atomic, write_json_atomic, write_text_atomic

__all__ = ["save_npz_atomic", "write_json_atomic", "write_text_atomic"]

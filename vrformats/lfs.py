"""Git LFS pointers: what a cloned dataset holds where a large file should be until ``git lfs pull``.

One home for the test, used by every reader of dataset files (GLBs, textures, navmeshes)."""

from __future__ import annotations

LFS_POINTER_PREFIX = b"version https://git-lfs.github.com/spec/v1"
LFS_HINT = "is a Git LFS pointer, not the file itself (run git lfs pull)"


def is_lfs_pointer(data_or_path) -> bool:
    """The bytes (or the file's first bytes) are a Git LFS pointer: text starting with the spec line."""
    if isinstance(data_or_path, (bytes, bytearray, memoryview)):
        head = bytes(data_or_path[: len(LFS_POINTER_PREFIX)])
    else:
        try:
            with open(data_or_path, "rb") as f:
                head = f.read(len(LFS_POINTER_PREFIX))
        except OSError:
            return False
    return head == LFS_POINTER_PREFIX

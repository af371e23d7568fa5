"""Shared fixtures of the test suite.

``make_tour``: the one factory of tour folders for tests that make tours without a renderer (a plain
function, ``from conftest import make_tour``): poses, frames and metadata written by the format's own
writer, ``vrformats.tour.write_tour``, so a test's tour is read exactly as a rendered one.

``smoke_reference``: the shipped smoke render job (tests/jobspecs.SMOKE: 36 frames, Blender, tiny
images) rendered once per session with the local backend and two workers. The tests that check
that another way of rendering it (killed and resumed, the Ray backend, each Ray runtime env) gives
the same job compare against this one folder instead of each rendering its own reference. Read it,
never write into it.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from jobspecs import SMOKE


def pytest_configure(config):
    """The render cache (``synth.render.cache``) of this test process: a fresh folder, never the user's."""
    import os
    import tempfile

    os.environ["SYNTH_CACHE_DIR"] = tempfile.mkdtemp(prefix="synth_cache_tests_")


def make_tour(root, poses, frames=None, *, intrinsics, fps=30.0, frame_ids=None, objects=None, **meta) -> Path:
    """A tour folder at ``root`` (made with its parents): ``poses`` camera-to-world, ``frames`` frame id ->
    channels (``rgb``, ``depth``, ``instance``, ``semantic``; None: poses only), ``meta`` over the
    writer's placeholders (``layout``, ``lighting``, ``path``, ``renderer``, anything else). Returns ``root``."""
    from vrformats.tour import write_tour

    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    write_tour(root, poses, intrinsics, frames, fps=fps, frame_ids=frame_ids, objects=objects, meta=meta)
    return root


@pytest.fixture(scope="session")
def smoke_reference(tmp_path_factory):
    from synth import jobs

    out = tmp_path_factory.mktemp("smoke_reference") / "job"
    summary = jobs.run_job(jobs.load_spec(SMOKE), out, workers=2, progress=False)
    assert summary["failed"] == {}, summary["failed"]
    return out

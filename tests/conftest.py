"""Shared fixtures of the test suite.

``smoke_reference``: the shipped smoke render job (tests/jobspecs.SMOKE: 36 frames, Blender, tiny
images) rendered once per session with the local backend and two workers. The tests that check
that another way of rendering it (killed and resumed, the Ray backend, each Ray runtime env) gives
the same job compare against this one folder instead of each rendering its own reference. Read it,
never write into it.
"""

from __future__ import annotations

import pytest

from jobspecs import SMOKE


@pytest.fixture(scope="session")
def smoke_reference(tmp_path_factory):
    from synth import jobs

    out = tmp_path_factory.mktemp("smoke_reference") / "job"
    summary = jobs.run_job(jobs.load_spec(SMOKE), out, workers=2, progress=False)
    assert summary["failed"] == {}, summary["failed"]
    return out

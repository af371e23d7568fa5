"""Render jobs: YAML specs, the resumable runner, local and Ray execution, storage and cost estimates.

``spec``        the job spec: parsing and validation (``load_spec``, ``JobSpec``)
``plan``        the spec expanded into tours and chunks (``expand``)
``state``       ``job_state.json`` and the chunk states
``chunk_queue`` the chunk queue, the progress bar and the local backend
``runner``      ``run_job``: a whole job, resumable, locally or on Ray
``ray_backend`` the Ray cluster backend (runtime env, preflight)
``storage``     a job's folder on an fsspec file system (local, shared, object store)
``calibration`` seconds per frame measured here, and the estimate for this machine
``estimate``    a job's wall time on a Ray cluster, from a calibration
``cli``         ``synth render SPEC`` and its dry run
"""

from .plan import Chunk, Plan, expand
from .runner import run_job
from .spec import JobSpec, load_spec, parse_spec, spec_document
from .state import STATE_FILE, JobState

__all__ = ["Chunk", "JobSpec", "JobState", "Plan", "STATE_FILE", "expand", "load_spec", "parse_spec", "run_job",
           "spec_document"]

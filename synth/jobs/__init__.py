"""Render jobs: YAML specs, the resumable runner, local and Ray execution, storage and cost estimates.

``job``         spec parsing, the job plan, state and the local runner
``ray_backend`` the Ray cluster backend (runtime env, preflight)
``storage``     a job's folder on an fsspec file system (local, shared, object store)
``estimate``    a job's wall time on a Ray cluster, from a calibration render
"""

"""A multi-node Ray cluster on loopback whose nodes run a Python of their own, as on separate machines.

``start(tmp, env=...)`` makes a *node Python* (a venv that sees this test venv's packages through a
``.pth`` file: a node on which the toolkit's requirements are installed, but whose environment Ray
clones for a pip runtime env, a few MB, not this venv's GBs), and starts, in a child process group
running that Python, ``ray.cluster_utils.Cluster`` with a head and one worker node, one CPU each,
each with its own runtime-env folder (on one machine they would otherwise share one and race to
build the same virtualenv). ``stop`` ends the group, whatever happens to the test.

Run as a script by ``start``: ``python ray_loopback.py INFO_JSON``.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import sysconfig
import time
from pathlib import Path

NODE_DIRS = ("runtime_resources_head", "runtime_resources_worker")


def node_python(root: Path) -> Path:
    """A venv without packages of its own that imports this venv's (pip, Ray and the toolkit's requirements)."""
    venv = root / "node_venv"
    if not (venv / "bin" / "python").exists():
        subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
        site = next((venv / "lib").glob("python3.*")) / "site-packages"
        (site / "_test_venv.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    return venv / "bin" / "python"


class Loopback:
    def __init__(self, proc: subprocess.Popen, info: dict):
        self.proc, self.info = proc, info
        self.address, self.session_dir = info["address"], Path(info["session_dir"])

    def runtime_env_dirs(self) -> list[Path]:
        return [self.session_dir / d for d in NODE_DIRS]

    def stop(self) -> None:
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(timeout=60)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()


def start(root: Path, env: dict | None = None, timeout: float = 120.0) -> Loopback:
    root.mkdir(parents=True, exist_ok=True)
    info_path = root / "cluster.json"
    info_path.unlink(missing_ok=True)
    py = node_python(root)
    proc = subprocess.Popen([str(py), __file__, str(info_path)], start_new_session=True,
                            env={**os.environ, "RAY_USAGE_STATS_ENABLED": "0", **(env or {})},
                            stdout=open(root / "cluster.log", "ab"), stderr=subprocess.STDOUT)
    t0 = time.monotonic()
    while not info_path.exists():
        if proc.poll() is not None or time.monotonic() - t0 > timeout:
            Loopback(proc, {"address": "", "session_dir": ""}).stop()
            raise RuntimeError(f"the loopback cluster did not start: {(root / 'cluster.log').read_text()[-2000:]}")
        time.sleep(0.5)
    return Loopback(proc, json.loads(info_path.read_text()))


def _serve(info_path: str) -> None:
    from ray.cluster_utils import Cluster

    c = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "runtime_env_dir_name": NODE_DIRS[0]})
    c.add_node(num_cpus=1, runtime_env_dir_name=NODE_DIRS[1])
    c.wait_for_nodes()
    session = c.head_node.get_session_dir_path()
    # the driver runs on this machine too and packs the working_dir into the default folder's name
    os.makedirs(os.path.join(session, "runtime_resources"), exist_ok=True)
    stopping = []
    signal.signal(signal.SIGTERM, lambda *_: stopping.append(1))
    tmp = info_path + ".tmp"
    Path(tmp).write_text(json.dumps({"address": c.address, "session_dir": session}))
    os.replace(tmp, info_path)
    while not stopping:
        time.sleep(0.2)
    c.shutdown()


if __name__ == "__main__":
    _serve(sys.argv[1])

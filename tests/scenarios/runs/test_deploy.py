"""scenarios/runs/deploy.py: what a Slurm or Kubernetes deployment of the engine's workers
gets (not run here): the documented blocks are what it writes, the manifest parses, and
each names the commands and settings the engine's local clusters use."""
import pathlib
import re

import yaml

from scenarios.runs import deploy, engine

PAGE = pathlib.Path(__file__).resolve().parents[3] / "docs" / "campaigns.md"


def _block(language):
    return re.search(rf"```{language}\n(.*?)```", PAGE.read_text(encoding="utf-8"), re.S).group(1)


def test_the_environment_is_the_engine_s_worker_config():
    env = deploy.environment()
    assert len(env) == len(engine.WORKER_CONFIG)
    assert env["DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED"] == "False"
    assert env["DASK_DISTRIBUTED__ADMIN__SYSTEM_MONITOR__INTERVAL"] == "5s"


def test_kubernetes_manifest_is_documented_and_runs_the_dask_commands():
    text = deploy.kubernetes_manifest(16)
    assert _block("yaml") == text
    scheduler, service, workers = yaml.safe_load_all(text)
    assert service["kind"] == "Service" and service["spec"]["ports"][0]["port"] == deploy.PORT
    for deployment, replicas, command in ((scheduler, 1, ["dask", "scheduler", "--port", "8786"]),
                                          (workers, 16, ["dask", "worker", "tcp://movingbase-scheduler:8786",
                                                         "--nthreads", "1", "--no-dashboard"])):
        [container] = deployment["spec"]["template"]["spec"]["containers"]
        assert deployment["spec"]["replicas"] == replicas and container["command"] == command
        assert container["image"] == deploy.IMAGE
        assert {e["name"]: e["value"] for e in container["env"]} == deploy.environment()
    assert _block("dockerfile") == deploy.DOCKERFILE
    assert "RUN pip install -c constraints.txt ." in deploy.DOCKERFILE and "gcc" in deploy.DOCKERFILE


def test_slurm_job_script_starts_one_single_threaded_worker_in_the_kit_s_venv():
    cluster = deploy.slurm_cluster(0, memory="2GB", walltime="00:30:00", checkout="/shared/movingbase")
    try:
        script = cluster.job_script()
        address = cluster.scheduler_address
    finally:
        cluster.close()
    lines = script.splitlines()
    assert lines[0] == "#!/usr/bin/env bash" and "#SBATCH -t 00:30:00" in lines and "#SBATCH --cpus-per-task=1" in lines
    activate = lines.index("source /shared/movingbase/.venv/bin/activate")
    exports = [f"export {k}={v}" for k, v in deploy.environment().items()]
    [worker] = [i for i, line in enumerate(lines) if "dask_worker" in line]
    assert all(activate < lines.index(e) < worker for e in exports)
    assert lines[worker].startswith(f"python -m distributed.cli.dask_worker {address} ")
    assert re.search(r"--nthreads 1\b", lines[worker]) and lines[worker].count("--nthreads") == 1

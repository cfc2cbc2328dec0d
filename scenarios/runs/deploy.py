"""Starting the engine's cluster elsewhere: a Slurm job script (dask-jobqueue's SLURMCluster)
and a Kubernetes manifest (a `dask scheduler` Deployment and Service, a `dask worker`
Deployment), each worker one thread, Dask's housekeeping slowed as on the engine's local
clusters (engine.WORKER_CONFIG), and this package installed where the workers run (the
FMUs import it at run time). docs/campaigns.md shows what these write; not run here.

    python -m scenarios.runs.deploy slurm                                # the job script
    python -m scenarios.runs.deploy kubernetes [--jobs 16] [--image IMAGE]   # the manifest
    python -m scenarios.runs.deploy dockerfile                           # the workers' image
"""
import argparse

INSTALL = "pip install -c constraints.txt ."     # run in a checkout of this repository (its pinned versions)
IMAGE = "movingbase:latest"                       # an image built from DOCKERFILE
PORT = 8786
# The workers' image: the kit installed as pinned, with a C compiler (the cffi kernels
# build at install; FMUs build on first use). Built from a checkout: docker build -t IMAGE .
DOCKERFILE = f"""FROM python:3.11-slim
RUN apt-get update && apt-get install -y --no-install-recommends gcc libc6-dev && rm -rf /var/lib/apt/lists/*
COPY . /src
WORKDIR /src
RUN {INSTALL}
"""


def environment():
    """{DASK_... variable: value} of engine.WORKER_CONFIG, as Dask reads its config from the
    environment (dots -> __, dashes -> _)."""
    from scenarios.runs.engine import WORKER_CONFIG
    return {"DASK_" + key.upper().replace(".", "__").replace("-", "_"): str(value)
            for key, value in WORKER_CONFIG.items()}


def slurm_cluster(jobs=16, memory="4GB", walltime="04:00:00", checkout="$HOME/movingbase", **kwargs):
    """A dask-jobqueue SLURMCluster whose every job is one single-threaded `dask worker`
    in the virtual environment of ``checkout`` (made with INSTALL once, on a shared disk);
    ``cluster.scale(jobs=N)`` submits N. The client runs `movingbase campaign FILE --dask
    cluster.scheduler_address`, or Engine(address=...)."""
    from dask_jobqueue import SLURMCluster
    prologue = [f"source {checkout}/.venv/bin/activate"] + [f"export {k}={v}" for k, v in environment().items()]
    cluster = SLURMCluster(cores=1, processes=1, memory=memory, walltime=walltime, python="python",
                           job_script_prologue=prologue,
                           scheduler_options={"dashboard_address": None}, **kwargs)
    cluster.scale(jobs=jobs)
    return cluster


def kubernetes_manifest(workers=16, image=IMAGE):
    """The manifest (YAML text): scheduler Deployment + Service on PORT, ``workers`` worker
    pods of one thread; `kubectl apply -f` it, then `movingbase campaign FILE --dask
    tcp://<the service's address>:8786` from a pod or a port-forward."""
    env = "".join(f"\n        - {{name: {k}, value: \"{v}\"}}" for k, v in environment().items())

    def deployment(name, replicas, command):
        return f"""apiVersion: apps/v1
kind: Deployment
metadata: {{name: movingbase-{name}}}
spec:
  replicas: {replicas}
  selector: {{matchLabels: {{app: movingbase-{name}}}}}
  template:
    metadata: {{labels: {{app: movingbase-{name}}}}}
    spec:
      containers:
      - name: {name}
        image: {image}
        command: {command}
        resources: {{requests: {{cpu: "1"}}, limits: {{cpu: "1"}}}}
        env:{env}
"""
    service = f"""apiVersion: v1
kind: Service
metadata: {{name: movingbase-scheduler}}
spec:
  selector: {{app: movingbase-scheduler}}
  ports:
  - {{port: {PORT}, targetPort: {PORT}}}
"""
    return "---\n".join([deployment("scheduler", 1, f'["dask", "scheduler", "--port", "{PORT}"]'), service,
                         deployment("worker", workers, f'["dask", "worker", "tcp://movingbase-scheduler:{PORT}", '
                                                      '"--nthreads", "1", "--no-dashboard"]')])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("kind", choices=("slurm", "kubernetes", "dockerfile"))
    parser.add_argument("--jobs", type=int, default=16, help="worker processes (Slurm jobs or pods)")
    parser.add_argument("--image", default=IMAGE, help="the workers' image (kubernetes)")
    args = parser.parse_args(argv)
    if args.kind != "slurm":
        print(kubernetes_manifest(args.jobs, args.image) if args.kind == "kubernetes" else DOCKERFILE, end="")
        return
    cluster = slurm_cluster(0)
    try:
        print(cluster.job_script())
    finally:
        cluster.close()


if __name__ == "__main__":
    main()

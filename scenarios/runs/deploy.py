"""Starting the engine's cluster elsewhere: a Slurm job script (dask-jobqueue's SLURMCluster)
and a Kubernetes manifest (a `dask scheduler` Deployment and Service, a `dask worker`
Deployment), each worker one thread, Dask's housekeeping slowed as on the engine's local
clusters (engine.WORKER_CONFIG), and this package installed where the workers run (the
FMUs import it at run time). docs/campaigns.md shows what these write; not run here.

A Dask scheduler runs whatever code it is sent, on every worker: whoever reaches it runs
code as the workers' user. So every deployment here speaks TLS with credentials (Dask's
distributed.security.Security, mutual: scheduler, workers and client each show a
certificate of one CA): the Slurm cluster's are made per cluster (Security.temporary()),
Kubernetes' by ``credentials`` into a folder that becomes a Secret; the manifest adds a
NetworkPolicy that admits only the kit's pods, and the image runs as a user that is not
root. What each protects against, and what not: docs/campaigns.md. Every argument is
checked before anything is written.

    python -m scenarios.runs.deploy slurm                                # the job script
    python -m scenarios.runs.deploy credentials DIR                      # CA, certificate, key
    python -m scenarios.runs.deploy kubernetes [--jobs 16] [--image IMAGE]   # the manifest
    python -m scenarios.runs.deploy dockerfile                           # the workers' image
"""
import argparse
import operator
import os
import pathlib
import re
import shlex
import sys

from fmu_src import atomic

INSTALL = "pip install -c constraints.txt ."     # run in a checkout of this repository (its pinned versions)
CLUSTER_EXTRA = "pip install -c constraints.txt -e '.[cluster]'"   # dask-jobqueue, in a clone
IMAGE = "movingbase:latest"                       # an image built from DOCKERFILE
PORT = 8786
UID = 10001                                       # the image's user: not root
PART_OF = "app.kubernetes.io/part-of"             # the label of the kit's pods (the NetworkPolicy admits these)
SECRET, TLS_MOUNT = "movingbase-tls", "/etc/movingbase-tls"
TLS_FILES = {"ca_file": "ca.pem", "cert": "cert.pem", "key": "key.pem"}
# The workers' image: the kit installed as pinned, with a C compiler (the cffi kernels
# build at install; FMUs build on first use, under /src, which the user owns). Built from a
# checkout: docker build -t IMAGE .
DOCKERFILE = f"""FROM python:3.11-slim
RUN apt-get update && apt-get install -y --no-install-recommends gcc libc6-dev && rm -rf /var/lib/apt/lists/*
RUN useradd --create-home --uid {UID} movingbase
COPY --chown={UID}:{UID} . /src
WORKDIR /src
RUN {INSTALL} && chown -R {UID}:{UID} /src
USER {UID}
"""


class DeployError(ValueError):
    """An argument of a deployment that would write a broken or unsafe file; says which and why."""


def environment():
    """{DASK_... variable: value} of engine.WORKER_CONFIG, as Dask reads its config from the
    environment (dots -> __, dashes -> _)."""
    from scenarios.runs.engine import WORKER_CONFIG
    return {"DASK_" + key.upper().replace(".", "__").replace("-", "_"): str(value)
            for key, value in WORKER_CONFIG.items()}


def tls_environment(folder):
    """The variables that give a Dask client the credentials in ``folder`` (``credentials``)
    and refuse plain tcp: `movingbase campaign FILE --dask tls://...` reads them."""
    folder = pathlib.Path(folder)
    return {"DASK_DISTRIBUTED__COMM__REQUIRE_ENCRYPTION": "True",
            "DASK_DISTRIBUTED__COMM__TLS__CA_FILE": str(folder / TLS_FILES["ca_file"]),
            "DASK_DISTRIBUTED__COMM__TLS__CLIENT__CERT": str(folder / TLS_FILES["cert"]),
            "DASK_DISTRIBUTED__COMM__TLS__CLIENT__KEY": str(folder / TLS_FILES["key"])}


def _count(name, value, low):
    """``value`` as an int >= low (any integer type; not a bool), else DeployError naming it."""
    try:
        if isinstance(value, bool):
            raise TypeError
        value = operator.index(value)
    except TypeError:
        raise DeployError(f"{name} must be an integer >= {low}, got {type(value).__name__} {value!r:.60}") from None
    if value < low:
        raise DeployError(f"{name} must be an integer >= {low}, got {value}")
    return value


def _text(name, value, pattern, example):
    if not isinstance(value, str) or not re.fullmatch(pattern, value):
        raise DeployError(f"{name} {value!r:.80}: expected e.g. {example!r} ({'empty' if value == '' else 'not one'})")
    return value


def credentials(folder):
    """A CA and one certificate and key it signed (Security.temporary(): every role shows the
    same), written to ``folder`` (made 0700; the key 0600, each file whole or not at all).
    Returns the paths {ca_file, cert, key}. Whoever holds these files can use the cluster."""
    from distributed.security import Security
    folder = pathlib.Path(_text("credentials folder", str(folder), r"[^\0\n]+", "tls"))
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    os.chmod(folder, 0o700)
    made = Security.temporary()
    paths = {}
    for role, name in TLS_FILES.items():
        paths[role] = folder / name
        text = {"ca_file": made.tls_ca_file, "cert": made.tls_client_cert, "key": made.tls_client_key}[role]
        with atomic.replacing(paths[role], text=True) as file:
            os.chmod(file.name, 0o600)
            file.write(text)
    return paths


def _shell_path(path):
    """``path`` for a shell line: quoted (a space in a checkout's path breaks nothing), with a
    leading $HOME or ~ left to the job's shell."""
    for home in ("$HOME/", "~/"):
        if path.startswith(home):
            return '"$HOME"/' + shlex.quote(path[len(home):])
    return shlex.quote(path)


def slurm_cluster(jobs=16, memory="4GB", walltime="04:00:00", checkout="$HOME/movingbase",
                  credentials_dir="$HOME/.movingbase-tls", **kwargs):
    """A dask-jobqueue SLURMCluster whose every job is one single-threaded `dask worker`
    in the virtual environment of ``checkout`` (made with INSTALL once, on a shared disk);
    ``cluster.scale(jobs=N)`` submits N. It speaks TLS with credentials made for it alone
    (Security.temporary(); the workers' copies are files in ``credentials_dir`` on the
    shared disk, 0600, removed when the cluster closes). The client runs in this process:
    Engine(address=cluster.scheduler_address, security=cluster.security)."""
    jobs = _count("jobs", jobs, 0)
    _text("memory", memory, r"\d+(\.\d+)?\s*[KMGT]i?B", "4GB")
    _text("walltime", walltime, r"(\d+-)?\d{1,3}:\d\d:\d\d", "04:00:00")
    _text("checkout", checkout, r"[^\0\n\r]+", "$HOME/movingbase")
    _text("credentials_dir", credentials_dir, r"(\$HOME/|~/|/)[\w./-]+", "$HOME/.movingbase-tls")
    try:
        from dask_jobqueue import SLURMCluster
    except ModuleNotFoundError:
        raise DeployError("deploy slurm needs dask-jobqueue, the kit's 'cluster' extra: in the checkout, "
                          f"{CLUSTER_EXTRA}") from None
    from distributed.security import Security
    shared = pathlib.Path(os.path.expandvars(os.path.expanduser(credentials_dir)))
    shared.mkdir(mode=0o700, parents=True, exist_ok=True)
    os.chmod(shared, 0o700)
    prologue = [f"source {_shell_path(checkout + '/.venv/bin/activate')}"] + \
        [f"export {k}={shlex.quote(v)}" for k, v in environment().items()]
    class Cluster(SLURMCluster):
        def close(self, *args, **kwargs):
            """The cluster closed, and the workers' credential files removed now (not when
            the object is collected)."""
            try:
                return super().close(*args, **kwargs)
            finally:
                for role in ("ca_file", "cert", "key"):
                    if getattr(self, f"_job_{role}", None) is not None:
                        getattr(self, f"_job_{role}").close()

    cluster = Cluster(cores=1, processes=1, memory=memory, walltime=walltime, python="python",
                           job_script_prologue=prologue, security=Security.temporary(),
                           shared_temp_directory=credentials_dir,
                           scheduler_options={"dashboard_address": None}, **kwargs)
    cluster.scale(jobs=jobs)
    return cluster


def kubernetes_manifest(workers=16, image=IMAGE):
    """The manifest (YAML text): scheduler Deployment + Service on PORT, ``workers`` worker
    pods of one thread, every pod a non-root user with the TLS credentials of the Secret
    SECRET (``credentials``, then `kubectl create secret generic movingbase-tls
    --from-file=DIR`), and a NetworkPolicy that admits to the kit's pods only pods labelled
    PART_OF=movingbase; `kubectl apply -f` it, then `movingbase campaign FILE --dask
    tls://movingbase-scheduler:8786` from a pod of that label, with tls_environment set."""
    workers = _count("workers (--jobs)", workers, 1)
    image = _text("image", image, r"[A-Za-z0-9][A-Za-z0-9._/:@-]*", IMAGE)
    env = "".join(f"\n        - {{name: {k}, value: \"{v}\"}}" for k, v in
                  {**environment(), "DASK_DISTRIBUTED__COMM__REQUIRE_ENCRYPTION": "True"}.items())
    tls = ", ".join(f'"--tls-{flag}", "{TLS_MOUNT}/{name}"' for flag, name in
                    (("ca-file", TLS_FILES["ca_file"]), ("cert", TLS_FILES["cert"]), ("key", TLS_FILES["key"])))

    def deployment(name, replicas, command):
        return f"""apiVersion: apps/v1
kind: Deployment
metadata: {{name: movingbase-{name}}}
spec:
  replicas: {replicas}
  selector: {{matchLabels: {{app: movingbase-{name}}}}}
  template:
    metadata: {{labels: {{app: movingbase-{name}, {PART_OF}: movingbase}}}}
    spec:
      securityContext: {{runAsNonRoot: true, runAsUser: {UID}, runAsGroup: {UID}}}
      containers:
      - name: {name}
        image: {image}
        command: {command}
        securityContext: {{allowPrivilegeEscalation: false, capabilities: {{drop: [ALL]}}}}
        resources: {{requests: {{cpu: "1"}}, limits: {{cpu: "1"}}}}
        volumeMounts: [{{name: tls, mountPath: {TLS_MOUNT}, readOnly: true}}]
        env:{env}
      volumes: [{{name: tls, secret: {{secretName: {SECRET}, defaultMode: 0400}}}}]
"""
    service = f"""apiVersion: v1
kind: Service
metadata: {{name: movingbase-scheduler}}
spec:
  selector: {{app: movingbase-scheduler}}
  ports:
  - {{port: {PORT}, targetPort: {PORT}}}
"""
    policy = f"""apiVersion: networking.k8s.io/v1
kind: NetworkPolicy
metadata: {{name: movingbase}}
spec:
  podSelector: {{matchLabels: {{{PART_OF}: movingbase}}}}
  policyTypes: [Ingress]
  ingress:
  - from:
    - podSelector: {{matchLabels: {{{PART_OF}: movingbase}}}}
"""
    return "---\n".join([deployment("scheduler", 1, f'["dask", "scheduler", "--port", "{PORT}", "--protocol", '
                                                    f'"tls", {tls}]'), service, policy,
                         deployment("worker", workers, f'["dask", "worker", "tls://movingbase-scheduler:{PORT}", '
                                                      f'"--nthreads", "1", "--no-dashboard", {tls}]')])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("kind", choices=("slurm", "kubernetes", "dockerfile", "credentials"))
    parser.add_argument("folder", nargs="?", help="credentials: the folder the CA, certificate and key go to")
    parser.add_argument("--jobs", type=int, default=16, help="worker processes (Slurm jobs or pods)")
    parser.add_argument("--image", default=IMAGE, help="the workers' image (kubernetes)")
    args = parser.parse_args(argv)
    try:
        if args.kind == "credentials":
            if not args.folder:
                parser.error("credentials needs the folder to write to: credentials DIR")
            paths = credentials(args.folder)
            folder = paths["ca_file"].parent.resolve()
            print(f"wrote {', '.join(p.name for p in paths.values())} to {folder} (the key: whoever holds it can "
                  f"use the cluster). For Kubernetes: kubectl create secret generic {SECRET} --from-file={folder}\n"
                  "A client (movingbase campaign FILE --dask tls://HOST:8786) reads them from:")
            print("\n".join(f"export {k}={shlex.quote(v)}" for k, v in tls_environment(folder).items()))
        elif args.kind == "slurm":
            cluster = slurm_cluster(0)
            try:
                print(cluster.job_script())
            finally:
                cluster.close()
        else:
            print(kubernetes_manifest(args.jobs, args.image) if args.kind == "kubernetes" else DOCKERFILE, end="")
    except DeployError as exc:
        sys.exit(f"deploy error: {exc}")


if __name__ == "__main__":
    main()

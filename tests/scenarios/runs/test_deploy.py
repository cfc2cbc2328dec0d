"""scenarios/runs/deploy.py: what a Slurm or Kubernetes deployment of the engine's workers
gets (not run here): the documented blocks are what it writes, the manifest parses, and
each names the commands and settings the engine's local clusters use."""
import pathlib
import re
import subprocess
import sys

import numpy as np
import pytest
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
    scheduler, service, policy, workers = yaml.safe_load_all(text)
    assert service["kind"] == "Service" and service["spec"]["ports"][0]["port"] == deploy.PORT
    tls = ["--tls-ca-file", "/etc/movingbase-tls/ca.pem", "--tls-cert", "/etc/movingbase-tls/cert.pem",
           "--tls-key", "/etc/movingbase-tls/key.pem"]
    for deployment, replicas, command in ((scheduler, 1, ["dask", "scheduler", "--port", "8786", "--protocol", "tls",
                                                          *tls]),
                                          (workers, 16, ["dask", "worker", "tls://movingbase-scheduler:8786",
                                                         "--nthreads", "1", "--no-dashboard", *tls])):
        pod = deployment["spec"]["template"]
        [container] = pod["spec"]["containers"]
        assert deployment["spec"]["replicas"] == replicas and container["command"] == command
        assert container["image"] == deploy.IMAGE
        assert {e["name"]: e["value"] for e in container["env"]} == {
            **deploy.environment(), "DASK_DISTRIBUTED__COMM__REQUIRE_ENCRYPTION": "True"}
        assert pod["metadata"]["labels"]["app.kubernetes.io/part-of"] == "movingbase"
        assert pod["spec"]["securityContext"] == {"runAsNonRoot": True, "runAsUser": 10001, "runAsGroup": 10001}
        assert pod["spec"]["volumes"] == [{"name": "tls", "secret": {"secretName": "movingbase-tls",
                                                                     "defaultMode": 0o400}}]
    # the policy selects every pod of the kit and admits traffic from those pods alone
    assert policy["kind"] == "NetworkPolicy" and policy["spec"]["policyTypes"] == ["Ingress"]
    assert policy["spec"]["podSelector"] == {"matchLabels": {"app.kubernetes.io/part-of": "movingbase"}}
    assert policy["spec"]["ingress"] == [{"from": [{"podSelector": policy["spec"]["podSelector"]}]}]
    assert _block("dockerfile") == deploy.DOCKERFILE
    lines = deploy.DOCKERFILE.splitlines()
    assert "RUN pip install -c constraints.txt . && chown -R 10001:10001 /src" in lines and "gcc" in deploy.DOCKERFILE
    assert lines[-1] == "USER 10001" and "RUN useradd --create-home --uid 10001 movingbase" in lines


@pytest.mark.parametrize("workers, image, problem", [
    (-3, "movingbase:latest", "workers (--jobs) must be an integer >= 1, got -3"),
    (0, "movingbase:latest", "workers (--jobs) must be an integer >= 1, got 0"),
    (True, "movingbase:latest", "must be an integer >= 1, got bool True"),
    ("3", "movingbase:latest", "must be an integer >= 1, got str '3'"),
    (2.0, "movingbase:latest", "must be an integer >= 1, got float 2.0"),
    (2, "", "image '': expected e.g. 'movingbase:latest' (empty)"),
    (2, "my image", "image 'my image'"),
    (2, "x\n  hostNetwork: true", "image 'x\\n  hostNetwork: true'"),
])
def test_a_manifest_that_would_be_broken_is_refused_before_it_is_written(workers, image, problem):
    with pytest.raises(deploy.DeployError) as info:
        deploy.kubernetes_manifest(workers, image)
    assert problem in str(info.value)
    assert yaml.safe_load_all(deploy.kubernetes_manifest(np.int64(3), "registry.example/mb@sha256:ab12"))


def test_the_command_line_refuses_bad_arguments_naming_them(capsys):
    for argv, said in ((["kubernetes", "--jobs", "-3"], "got -3"), (["kubernetes", "--image", ""], "image ''")):
        with pytest.raises(SystemExit, match=f"deploy error: .*{re.escape(said)}"):
            deploy.main(argv)
    assert capsys.readouterr().out == ""       # nothing written


def test_slurm_without_dask_jobqueue_names_the_extra_and_its_install_command(monkeypatch):
    monkeypatch.setitem(sys.modules, "dask_jobqueue", None)     # import fails as if not installed
    with pytest.raises(SystemExit, match=re.escape("deploy error: deploy slurm needs dask-jobqueue, the kit's "
                                                   "'cluster' extra: in the checkout, pip install -c constraints.txt "
                                                   "-e '.[cluster]'")):
        deploy.main(["slurm"])


def test_slurm_arguments_are_checked_first():
    for kwargs, said in (({"jobs": -1}, "jobs must be an integer >= 0"), ({"memory": "lots"}, "memory 'lots'"),
                         ({"walltime": "4h"}, "walltime '4h'"), ({"checkout": ""}, "checkout ''"),
                         ({"credentials_dir": "tls dir"}, "credentials_dir 'tls dir'")):
        with pytest.raises(deploy.DeployError, match=re.escape(said)):
            deploy.slurm_cluster(**kwargs)


def test_slurm_job_script_starts_one_single_threaded_worker_in_the_kit_s_venv(tmp_path):
    cluster = deploy.slurm_cluster(0, memory="2GB", walltime="00:30:00", checkout="/shared/movingbase",
                                   credentials_dir=str(tmp_path / "tls"))
    try:
        script = cluster.job_script()
        address = cluster.scheduler_address
        files = sorted((tmp_path / "tls").iterdir())
        assert [f.stat().st_mode & 0o777 for f in files] == [0o600] * 3     # the workers' copies: CA, cert, key
        assert (tmp_path / "tls").stat().st_mode & 0o777 == 0o700
    finally:
        cluster.close()
    assert not list((tmp_path / "tls").iterdir())                           # removed with the cluster
    lines = script.splitlines()
    assert lines[0] == "#!/usr/bin/env bash" and "#SBATCH -t 00:30:00" in lines and "#SBATCH --cpus-per-task=1" in lines
    activate = lines.index("source /shared/movingbase/.venv/bin/activate")
    assert address.startswith("tls://")
    for flag in ("--tls-ca-file", "--tls-cert", "--tls-key"):
        assert f"{flag} {tmp_path / 'tls'}/.dask-jobqueue.worker." in script
    exports = [f"export {k}={v}" for k, v in deploy.environment().items()]
    [worker] = [i for i, line in enumerate(lines) if "dask_worker" in line]
    assert all(activate < lines.index(e) < worker for e in exports)
    assert lines[worker].startswith(f"python -m distributed.cli.dask_worker {address} ")
    assert re.search(r"--nthreads 1\b", lines[worker]) and lines[worker].count("--nthreads") == 1


@pytest.mark.parametrize("checkout, home, path", [
    ("/shared/my movingbase", "/unused", "/shared/my movingbase/.venv/bin/activate"),
    ("$HOME/my checkout's copy", "/home/a b", "/home/a b/my checkout's copy/.venv/bin/activate"),
    ("~/movingbase", "/home/u", "/home/u/movingbase/.venv/bin/activate"),
])
def test_the_prologue_s_paths_survive_spaces_and_quotes(tmp_path, checkout, home, path):
    """The source line as bash reads it (the job's own shell), $HOME expanded there."""
    cluster = deploy.slurm_cluster(0, checkout=checkout, credentials_dir=str(tmp_path / "tls"))
    try:
        [line] = [x for x in cluster.job_script().splitlines() if x.startswith("source ")]
    finally:
        cluster.close()
    said = subprocess.run(["bash", "-c", "source() { printf '%s' \"$1\"; }; " + line], env={"HOME": home},
                          capture_output=True, text=True, check=True).stdout
    assert said == path


def _security(folder):
    from distributed.security import Security
    return Security(tls_ca_file=str(folder / "ca.pem"), tls_client_cert=str(folder / "cert.pem"),
                    tls_client_key=str(folder / "key.pem"), require_encryption=True)


def test_a_tls_scheduler_refuses_clients_without_its_credentials(tmp_path):
    """A `dask scheduler` and `dask worker` started as the manifest starts them, on 127.0.0.1,
    with the credentials ``deploy credentials`` writes: the engine with them runs a task on
    the worker; a client with another CA's credentials, a TLS client with no certificate and
    a plain tcp client are each refused by the scheduler."""
    import socket
    import ssl

    from distributed import Client

    from scenarios.runs import engine
    mine = deploy.credentials(tmp_path / "mine")
    deploy.credentials(tmp_path / "other")
    assert {p.stat().st_mode & 0o777 for p in mine.values()} == {0o600}
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    address = f"tls://127.0.0.1:{port}"
    tls = ["--tls-ca-file", str(mine["ca_file"]), "--tls-cert", str(mine["cert"]), "--tls-key", str(mine["key"])]
    dask, quiet = [sys.executable, "-m", "dask"], {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    processes = [subprocess.Popen(dask + ["scheduler", "--protocol", "tls", "--host", "127.0.0.1", "--port", str(port),
                                          "--dashboard-address", ":0", *tls], **quiet)]
    try:
        processes.append(subprocess.Popen(dask + ["worker", address, "--nthreads", "1", "--no-dashboard",
                                                  "--local-directory", str(tmp_path / "worker"), *tls], **quiet))
        with engine.Engine(address=address, security=_security(tmp_path / "mine")) as eng:
            eng.client.wait_for_workers(1, timeout=60)
            assert eng.client.submit(pow, 3, 4, pure=False).result(timeout=60) == 81
        with pytest.raises((OSError, TimeoutError)):         # another CA: the handshake fails both ways
            Client(address, security=_security(tmp_path / "other"), timeout=5)
        with pytest.raises(engine.EngineError, match="did not take this client"):   # the engine says so
            engine.Engine(address=address, security=_security(tmp_path / "other")).client
        with pytest.raises(engine.EngineError, match="admits only clients with its credentials; this client has "
                                                     "none: set DASK_DISTRIBUTED__COMM__TLS__CA_FILE"):
            engine.Engine(address=address).client
        with pytest.raises((OSError, TimeoutError)):         # plain tcp to the TLS port: no answer it reads
            Client(f"tcp://127.0.0.1:{port}", timeout=5)
        context = ssl.create_default_context(cafile=str(mine["ca_file"]))
        context.check_hostname = False                       # Dask's certificates name no host
        with socket.create_connection(("127.0.0.1", port), timeout=5) as raw:   # no client certificate
            with pytest.raises((ssl.SSLError, ConnectionError)):
                with context.wrap_socket(raw) as wrapped:
                    wrapped.sendall(b"x")
                    wrapped.recv(1)     # TLS 1.3: the server's refusal arrives after the handshake
    finally:
        for process in processes[::-1]:
            process.terminate()
            process.wait(timeout=30)


def test_the_engine_s_local_cluster_admits_only_its_own_credentials():
    from distributed import Client
    from distributed.security import Security

    from scenarios.runs import engine
    with engine.Engine(jobs=1) as eng:
        assert eng.client.submit(pow, 2, 5, pure=False).result(timeout=60) == 32
        address = eng.cluster.scheduler_address
        assert address.startswith("tls://127.0.0.1:")
        with pytest.raises((OSError, TimeoutError)):         # another user's client, with credentials of its own
            Client(address, security=Security.temporary(), timeout=5)

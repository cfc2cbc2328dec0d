"""Sampled campaigns ([sample], issue 30): each sample's draws come from (seed, sample,
input) alone and follow their distribution; bad tables are refused naming file and key;
and on a real multi-process Dask cluster (scheduler and workers started apart, as a
deployment starts them) the results equal the LocalCluster's and a sequential run's bit
for bit, and one sample re-run alone equals its campaign result."""
import json
import socket
import subprocess
import sys

import numpy as np
import pytest
from scipy import stats

from scenarios.runs import campaign as campaigns
from scenarios.runs import engine

SCENE = campaigns.SHIPPED / "scenes" / "dynamic_budget.toml"
TABLE = '''
[sample]
samples = {samples}
seed = 7
seeds = ["imu.seed"]
"plant.payload_mass_error" = {{ distribution = "normal", sd = "40 kg" }}
"encoders.scale_error[2]" = {{ distribution = "uniform", half_width = "1e-4" }}
"imu.imu_alignment" = {{ distribution = "uniform", half_width = "1 mrad" }}
'''


def _file(tmp_path, samples=4, extra="", stop="1.05 s"):
    path = tmp_path / "sampled.toml"
    path.write_text(f'scenario = "{SCENE}"\nset = {{ stop_time = "{stop}" }}\n' + TABLE.format(samples=samples)
                    + extra)
    return path


def test_draws_follow_seed_sample_and_name_alone_and_their_distribution(tmp_path):
    sample = campaigns.load(_file(tmp_path)).sample
    assert [key for key, *_ in sample.inputs] == ["plant.payload_mass_error", "encoders.scale_error[2]",
                                                  "imu.imu_alignment[1]", "imu.imu_alignment[2]",
                                                  "imu.imu_alignment[3]"]
    more = campaigns.Sample(4, 7, sample.inputs[::-1] + (("plant.stroke", "plant", "stroke", "m",
                                                          sample.inputs[0][4]),), sample.seeds)
    for k in range(4):      # reordered, one more input: each input's draw stays
        mine, other = sample.draws(k), more.draws(k)
        assert all(other[0][key] == value for key, value in mine[0].items()) and mine[1] == other[1]
    assert sample.draws(1) != sample.draws(2)
    draws = [sample.draws(k) for k in range(2000)]
    mass = [d["plant.payload_mass_error"] for d, _ in draws]
    scale = [d["encoders.scale_error[2]"] for d, _ in draws]
    assert stats.kstest(mass, stats.norm(0, 40).cdf).pvalue > 1e-3
    assert stats.kstest(scale, stats.uniform(-1e-4, 2e-4).cdf).pvalue > 1e-3
    assert stats.kstest(mass, stats.norm(0, 50).cdf).pvalue < 1e-3      # the check can fail
    seeds = {s["imu.seed"] for _, s in draws}
    assert len(seeds) == 2000 and all(0 < s < 2 ** 31 for s in seeds)


def test_each_run_gets_the_scene_s_value_plus_its_draw(tmp_path):
    made = campaigns.CampaignJobs(campaigns.load(_file(tmp_path)))
    sample = made.campaign.sample
    for job, case in zip(made, made.campaign.cases):
        draws, seeds = sample.draws(case.sample)
        assert job.label == f"sample {case.sample}"
        assert job.parameters["plant"]["payload_mass_error"] == draws["plant.payload_mass_error"]   # default 0
        assert job.parameters["encoders"]["scale_error[2]"] == draws["encoders.scale_error[2]"]
        assert "scale_error[1]" not in job.parameters["encoders"]
        assert job.parameters["imu"]["imu_alignment[3]"] == draws["imu.imu_alignment[3]"]
        assert job.parameters["imu"]["seed"] == seeds["imu.seed"]
        assert job.parameters["imu"]["lever_arm"] == 25.0
    assert len({job.key for job in made}) == 4


@pytest.mark.parametrize("table, where, problem", [
    ('"plant.payload_mas" = { distribution = "normal", sd = "1 kg" }', "sample.plant.payload_mas",
     "has no parameter 'payload_mas'"),
    ('"plant.payload_mass_error" = { distribution = "normal", sd = "1 m" }', "sample.plant.payload_mass_error.sd",
     "'1 m'"),
    ('"nowhere.x" = { distribution = "normal", sd = "1 m" }', "sample.nowhere.x", "unknown key"),
    ('"plant.fidelity" = { distribution = "normal", sd = "1" }', "sample.plant.fidelity", "real parameter"),
    ('"plant.base_pose" = { distribution = "normal", sd = "1 m" }', "sample.plant.base_pose",
     "is an input, not a parameter"),
    ('"plant.stroke" = { distribution = "cauchy", sd = "1 m" }', "sample.plant.stroke", "'cauchy'"),
    ('seeds = ["plant.stroke"]\n"plant.stroke" = { distribution = "normal", sd = "1 mm" }', "sample.seeds[0]",
     "not an integer seed"),
    ('samples = 0\n"plant.stroke" = { distribution = "normal", sd = "1 mm" }', "sample.samples", ">= 1"),
])
def test_bad_sample_tables_are_refused_naming_file_and_key(tmp_path, table, where, problem):
    path = tmp_path / "bad.toml"
    path.write_text(f'scenario = "{SCENE}"\n[sample]\nsamples = 2\nseed = 1\n'.replace(
        "samples = 2\n", "" if "samples" in table else "samples = 2\n") + table + "\n")
    with pytest.raises(campaigns.CampaignError) as info:
        campaigns.load(path)
    assert f"{path}: {where}: " in str(info.value) and problem in str(info.value)


def test_a_draw_outside_the_parameter_s_range_is_refused_before_running(tmp_path):
    path = tmp_path / "wide.toml"
    path.write_text(f'scenario = "{SCENE}"\n[sample]\nsamples = 50\nseed = 1\n'
                    '"encoders.scale_error[1]" = { distribution = "normal", sd = "0.02" }\n')
    with pytest.raises(campaigns.CampaignError, match=r"wide.toml: sample \d+: encoders.scale_error\[1\]: the draw"):
        campaigns.jobs(campaigns.load(path))


def _same(a, b):
    """Two stores' (or a store's and a result's) metrics and series, bit for bit."""
    return a[0] == b[0] and a[1].keys() == b[1].keys() and all(
        np.array_equal(a[1][n][0], b[1][n][0]) and np.array_equal(a[1][n][1], b[1][n][1]) for n in a[1])


def _stored(store, key):
    return store.read(key)["metrics"], store.series(key)


@pytest.mark.slow
def test_multi_process_cluster_equals_local_and_sequential_and_a_sample_alone(tmp_path):
    path = _file(tmp_path, samples=6)
    sequential = {}
    for k in range(6):
        [(job, result, stored)] = campaigns.rerun_sample(path, k, out=tmp_path / "nothing")
        assert stored is None and result["status"] == "ok"
        sequential[job.key] = (json.loads(json.dumps(result["metrics"], default=float)), result["series"])
    _, jobs, local, outcome, summary = campaigns.run_campaign(path, tmp_path / "local", jobs_=2, progress=False)
    assert len(outcome.computed) == 6 and not outcome.failed

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    address, dask = f"tcp://127.0.0.1:{port}", [sys.executable, "-m", "dask"]
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    processes = [subprocess.Popen(dask + ["scheduler", "--host", "127.0.0.1", "--port", str(port),
                                          "--dashboard-address", ":0"], **quiet)]
    try:
        processes += [subprocess.Popen(dask + ["worker", address, "--nthreads", "1", "--no-dashboard",
                                               "--local-directory", str(tmp_path / f"worker{i}")], **quiet)
                      for i in range(2)]
        with engine.Engine(address=address) as eng:     # both worker processes there before the campaign
            eng.client.wait_for_workers(2, timeout=120)
        _, _, remote, outcome, _ = campaigns.run_campaign(path, tmp_path / "remote", address=address, progress=False)
        assert len(outcome.computed) == 6 and not outcome.failed
        workers = {remote.read(job.key)["worker"] for job in jobs}
    finally:
        for process in processes[::-1]:
            process.terminate()
            process.wait(timeout=30)
    assert len(workers) == 2
    for job in jobs:
        assert _same(_stored(local, job.key), sequential[job.key])
        assert _same(_stored(remote, job.key), sequential[job.key])
    [(job, result, stored)] = campaigns.rerun_sample(path, 3, out=tmp_path / "remote")
    assert stored is not None and result["same"]
    rows = summary.read_text().splitlines()
    assert rows[0].startswith("label,sample,plant.payload_mass_error [kg],encoders.scale_error[2],"
                              "imu.imu_alignment[1] [rad]")
    draws, seeds = campaigns.load(path).sample.draws(3)
    assert rows[4].split(",")[1:4] == ["3", repr(draws["plant.payload_mass_error"]),
                                       repr(draws["encoders.scale_error[2]"])]


@pytest.mark.parametrize("extra, where", [
    ('[[grid]]\n"encoders.seed" = [1, 2]\n', "grid[0].encoders.seed"),
    ('[grid]\n"imu.seed" = [1, 2]\n', "grid[0].imu.seed"),
    ('[[cases]]\nlabel = "a"\n"imu.seed" = 3\n', "cases[0].imu.seed"),
])
def test_a_seed_the_campaign_also_sets_is_refused_not_overridden(tmp_path, extra, where):
    path = _file(tmp_path, extra=extra.replace("imu.seed", "encoders.seed") if "cases" in extra else extra)
    path.write_text(path.read_text().replace('seeds = ["imu.seed"]', 'seeds = ["imu.seed", "encoders.seed"]'))
    where = where.replace("imu.seed", "encoders.seed") if "cases" in extra else where
    j = 1 if "encoders" in where else 0
    with pytest.raises(campaigns.CampaignError, match=rf"sampled.toml: sample.seeds\[{j}\]: .* also set in "
                                                      rf"{where.replace('[', '.').replace(']', '.')}: each sample"):
        campaigns.load(path)
    path.write_text(path.read_text().replace('seeds = ["imu.seed", "encoders.seed"]', "seeds = []"))
    assert len(campaigns.load(path).cases) == 2 * 4 if "grid" in extra else 4    # without seeds: it runs


def test_one_parameter_drawn_twice_or_a_seed_listed_twice_is_refused(tmp_path):
    path = _file(tmp_path, extra='"imu.imu_alignment[2]" = { distribution = "normal", sd = "1 mrad" }\n')
    with pytest.raises(campaigns.CampaignError, match=r"sample.imu.imu_alignment\[2\]: imu.imu_alignment\[2\] is "
                                                      "drawn by an earlier key"):
        campaigns.load(path)
    path = _file(tmp_path)
    path.write_text(path.read_text().replace('seeds = ["imu.seed"]', 'seeds = ["imu.seed", "imu.seed"]'))
    with pytest.raises(campaigns.CampaignError, match=r"sample.seeds\[1\]: imu.seed is listed twice"):
        campaigns.load(path)


def test_a_linked_parameter_is_sampled_around_a_set_value_or_refused(tmp_path):
    path = tmp_path / "linked.toml"
    table = '[sample]\nsamples = 2\nseed = 3\n"plant.initial_pose" = { distribution = "normal", sd = "1 mm" }\n'
    path.write_text(f'scenario = "{SCENE}"\n' + table)     # the scene links it: "@base.reference_pose"
    with pytest.raises(campaigns.CampaignError, match=r"linked.toml: sample.plant.initial_pose\[1\]: "
                                                      r"plant.initial_pose\[1\] is linked in dynamic_budget.toml to "
                                                      r"'@base.reference_pose\[1\]'.*set one for it"):
        campaigns.jobs(campaigns.load(path))
    pose = [0.001, 0, 0.002, 0, 0, 0.01]
    path.write_text(f'scenario = "{SCENE}"\nset = {{ "plant.initial_pose" = {pose} }}\n' + table)
    made = campaigns.CampaignJobs(campaigns.load(path))
    for job, case in zip(made, made.campaign.cases):
        draws = made.campaign.sample.draws(case.sample)[0]
        assert [job.parameters["plant"][f"initial_pose[{i}]"] for i in range(1, 7)] == \
            [p + draws[f"plant.initial_pose[{i}]"] for i, p in enumerate(pose, 1)]


def test_ci_sample_may_be_a_count_and_other_shapes_are_refused(tmp_path):
    path = _file(tmp_path, samples=30, extra="[ci]\nsample = 4\n")
    assert len(campaigns.load(path).cases) == 30
    ci = campaigns.load(path, ci=True)
    assert len(ci.cases) == 4 and ci.sample.samples == 4 and ci.sample.seed == 7     # the rest of [sample] kept
    path.write_text(path.read_text().replace("sample = 4", 'sample = "4"'))
    for ci in (False, True):        # checked without --ci too
        with pytest.raises(campaigns.CampaignError, match=r"sampled.toml: ci.sample: expected a table .* got '4'"):
            campaigns.load(path, ci=ci)
    path.write_text(f'scenario = "{SCENE}"\nsample = 4\n[ci]\nsample = {{ samples = 2 }}\n')
    with pytest.raises(campaigns.CampaignError, match=r"sampled.toml: sample: expected a table \(\[sample\]\), got 4"):
        campaigns.load(path, ci=True)
    path.write_text(f'scenario = "{SCENE}"\n[ci]\nset = 4\n')     # told as the [ci] key it is
    with pytest.raises(campaigns.CampaignError, match=r"sampled.toml: ci.set: expected a table, got 4"):
        campaigns.load(path, ci=True)


def test_sample_rerun_refuses_a_file_as_out_and_tells_a_damaged_result(tmp_path, capsys):
    from movingbase import cli
    path = _file(tmp_path, samples=2, stop="1.05 s")
    (tmp_path / "file").write_text("")
    with pytest.raises(SystemExit, match=r"campaign error: output folder .*file: a file, not a folder"):
        cli.main(["campaign", str(path), "--sample", "0", "--out", str(tmp_path / "file")])
    [(job, result, stored)] = campaigns.rerun_sample(path, 1, out=tmp_path / "out")
    assert stored is None and "damaged" not in result and not (tmp_path / "out").exists()   # writes nothing
    engine.Store(tmp_path / "out" / "sampled" / "runs").write(job, dict(result))
    [(_, again, stored)] = campaigns.rerun_sample(path, 1, out=tmp_path / "out")
    assert stored is not None and again["same"]
    with open(tmp_path / "out" / "sampled" / "runs" / f"{job.key}.npz", "r+b") as npz:
        npz.truncate(100)
    with pytest.raises(SystemExit) as info:
        cli.main(["campaign", str(path), "--sample", "1", "--out", str(tmp_path / "out")])
    assert info.value.code == 1
    said = capsys.readouterr().out
    assert f"DAMAGED on disk, not compared: {tmp_path / 'out' / 'sampled' / 'runs' / job.key}.npz: truncated" in said
    assert "not on disk" not in said

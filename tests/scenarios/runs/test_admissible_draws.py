"""Draws that no body can have (issue 38): a perturbed payload is checked against the laws of
a rigid body before anything runs, and a sampled campaign redraws a sample whose draws break
them, so every sample it runs is a body that can exist; a draw is added to the run's value
(the scene's), not to the FMU's start."""
import numpy as np
import pytest

import movingbase
from plant.errors import InvalidInputError
from plant.hexapod.model import StewartParams, body_problems, check_body
from scenarios import spec
from scenarios.runs import campaign as campaigns

SCENE = campaigns.SHIPPED / "scenes" / "dynamic_budget.toml"
PAPER = StewartParams.paper()


@pytest.mark.parametrize("mass, inertia, broken", [
    (2129.7, [3683.0, 3683.0, 6474.0], []),                   # the paper's platform
    (1.0, [1.0, 1.0, 2.0], []),                               # a thin disc: Izz = Ixx + Iyy exactly
    (1.0, [1.0, 1.0, 2.0 + 1e-9], ["Izz"]),                   # just beyond it
    (1.0, [3.0, 1.0, 1.0], ["Ixx"]),                          # each axis is checked
    (1.0, [1.0, 3.0, 1.0], ["Iyy"]),
    (1.0, [0.0, 1.0, 1.0], ["Ixx = 0 kg.m2 is not > 0"]),     # not positive definite
    (0.0, [1.0, 1.0, 1.0], ["mass 0 kg is not > 0"]),
    (-5.0, [1.0, 1.0, 1.0], ["mass -5 kg"]),
])
def test_body_laws_on_exactly_known_bodies(mass, inertia, broken):
    found = body_problems(mass, inertia)
    assert len(found) == len(broken) and all(b in f for b, f in zip(broken, found))
    if broken:
        with pytest.raises(InvalidInputError, match="no rigid body"):
            check_body(mass, inertia)


def test_the_issue_s_single_run_is_refused_before_it_runs_naming_the_input():
    # [-1841, -1841, 3237] kg.m2 on the paper's [3683, 3683, 6474]: Izz 9711 > Ixx + Iyy 3684 by 6027
    with pytest.raises(spec.ScenarioError) as caught:
        movingbase.run("telescope_slew", set={"plant.payload_inertia_error": [-1841, -1841, 3237]}, ci=True,
                       progress=False)
    text = str(caught.value)
    assert "fmus.plant.parameters" in text and "payload_inertia_error = [-1841, -1841, 3237] kg.m2" in text
    assert "Izz = 9711 kg.m2 exceeds Ixx+Iyy = 3684 kg.m2 by 6027 kg.m2" in text


def test_the_shipped_dynamic_budget_redraws_exactly_its_inadmissible_samples():
    made = campaigns.CampaignJobs(campaigns.load("dynamic_budget"))
    sample, first = made.campaign.sample, []
    for case, job in zip(made.campaign.cases, made):
        k = case.sample
        moments = PAPER.platform_inertia + [sample.draws(k)[0][f"plant.payload_inertia_error[{j}]"]
                                             for j in (1, 2, 3)]
        first.append(moments[0] + moments[1] - moments[2])
        ran = PAPER.platform_inertia + [job.parameters["plant"][f"payload_inertia_error[{j}]"] for j in (1, 2, 3)]
        assert body_problems(PAPER.platform_mass + job.parameters["plant"]["payload_mass_error"], ran) == []
        if made.redrawn[case.label] == 0:     # an admissible first draw runs as drawn
            assert job.parameters["plant"]["payload_mass_error"] == sample.draws(k)[0]["plant.payload_mass_error"]
        assert job.parameters["imu"]["seed"] == sample.draws(k)[1]["imu.seed"]   # the noise is the sample's
    short = -np.array(first)[np.array(first) < 0]
    # the issue's count: 12 of 256 samples short by 13-410 kg.m2
    assert len(short) == 12 and round(short.min()) == 13 and round(short.max()) == 410
    assert sorted(int(label.split()[1]) for label, a in made.redrawn.items() if a) == \
        [k for k, f in enumerate(first) if f < 0]


def test_a_distribution_of_mostly_impossible_bodies_is_refused(tmp_path):
    path = tmp_path / "impossible.toml"
    # Izz + 5000 +- 10 against Ixx + Iyy = 7366: every draw breaks Izz <= Ixx + Iyy (6474 + 5000 - 10 > 7366 + 20)
    path.write_text(f'scenario = "{SCENE}"\nset = {{ stop_time = "1.05 s", "plant.payload_inertia_error" = '
                    '["0 kg.m2", "0 kg.m2", "3000 kg.m2"] }\n[sample]\nsamples = 2\nseed = 1\n'
                    '"plant.payload_inertia_error" = { distribution = "uniform", half_width = "10 kg.m2" }\n')
    with pytest.raises(campaigns.CampaignError, match=r"sample 0: 101 draws in a row gave a body no model"):
        list(campaigns.CampaignJobs(campaigns.load(path)))


def test_a_draw_is_added_to_the_scene_s_value_not_the_fmu_start(tmp_path):
    # the scene sets encoders.rate_cutoff = 100 Hz, the FMU's start is 0
    path = tmp_path / "cutoff.toml"
    path.write_text(f'scenario = "{SCENE}"\nset = {{ stop_time = "1.05 s" }}\n[sample]\nsamples = 3\nseed = 5\n'
                    '"encoders.rate_cutoff" = { distribution = "uniform", half_width = "5 Hz" }\n')
    made = campaigns.CampaignJobs(campaigns.load(path))
    for case, job in zip(made.campaign.cases, made):
        draw = made.campaign.sample.draws(case.sample)[0]["encoders.rate_cutoff"]
        assert 0 < abs(draw) <= 5
        assert job.parameters["encoders"]["rate_cutoff"] == pytest.approx(100.0 + draw, abs=1e-12)


def test_the_summary_tells_the_draws_that_ran_not_the_first_ones(tmp_path):
    """summary.csv's input columns (what studies.dynamic_budget regresses on) hold a redrawn
    sample's second draws: each equals the run's parameter minus the scene's value (0)."""
    import csv

    from scenarios.runs import engine
    made = campaigns.CampaignJobs(campaigns.load("dynamic_budget"))
    path = campaigns.write_summary(made.campaign, engine.Store(tmp_path / "runs"), made, tmp_path / "summary.csv")
    with open(path, newline="", encoding="utf-8") as file:
        rows = {int(r["sample"]): r for r in csv.DictReader(file)}
    jobs = {case.sample: job for case, job in zip(made.campaign.cases, made)}
    for k in (23, 31, 0):       # two of the redrawn samples, one drawn once
        for j in (1, 2, 3):
            ran = jobs[k].parameters["plant"][f"payload_inertia_error[{j}]"]
            assert float(rows[k][f"plant.payload_inertia_error[{j}] [kg.m2]"]) == ran
        assert float(rows[k]["plant.payload_mass_error [kg]"]) == jobs[k].parameters["plant"]["payload_mass_error"]
    assert made.redrawn["sample 23"] > 0 and made.redrawn["sample 0"] == 0

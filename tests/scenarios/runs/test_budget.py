"""Budget files (scenarios/runs/budget.py): parsed with errors naming file, key and problem;
their quantiles against a first-order model sampled apart, Sobol group indices against the
analytic variance shares, the allocation against a fresh Monte Carlo and a plain scaling."""
import dataclasses
import json
import warnings

import numpy as np
import pytest
from scipy.stats import binom

from fmu_src import atomic
from plant.hexapod import tolerance as tl
from plant.hexapod.model import StewartParams
from scenarios.runs import budget as bg
from scenarios.runs import estimates as resources

SMALL = """
name = "small"
samples = 20000
sobol_samples = 1024
seed = 4
[inputs]
leg_offset = { distribution = "uniform", half_width = "20 um" }
base_joint = { distribution = "normal", sd = "10 um" }
base_joint_2_z = { distribution = "uniform", half_width = "0.1 mm" }
[workspace]
elevation = ["60 deg", "60 deg"]
[targets]
focus = "10 um"
position = "30 um"
"""


def test_shipped_budgets_parse():
    default, nanshan = bg.load("default"), bg.load("nanshan")
    assert default.groups == tuple(tl.GROUPS) and nanshan.groups == ("leg_offset", "base_joint", "platform_joint")
    assert nanshan.inputs[0].scale == pytest.approx(8e-5) and nanshan.inputs[20].scale == pytest.approx(4e-5)
    assert default.inputs[6].scale == 1e-4 and default.elevation == pytest.approx(np.radians([5, 90]))
    assert default.targets == pytest.approx({"focus": 1e-5, "position": 1e-4}) and default.probability == 0.997


def test_a_member_overrides_its_group_in_any_order():
    budget = bg.parse(SMALL)
    z2 = tl.INPUT_NAMES.index("base_joint_2_z")
    assert budget.inputs[z2].kind == "uniform" and budget.inputs[z2].scale == pytest.approx(1e-4)
    assert budget.inputs[z2 - 1].kind == "normal" and budget.inputs[tl.INPUT_NAMES.index("homing_1")] is None
    member = 'base_joint_2_z = { distribution = "uniform", half_width = "0.1 mm" }\n'
    reordered = SMALL.replace(member, "").replace("[inputs]\n", "[inputs]\n" + member)   # the member first
    assert reordered.index("base_joint_2_z") < reordered.index("base_joint =")
    assert bg.parse(reordered).inputs[z2].scale == pytest.approx(1e-4)


@pytest.mark.parametrize("change, key, problem", [
    (('leg_offset =', 'leg_ofset ='), "inputs.leg_ofset", "did you mean 'leg_offset'"),
    (('"20 um"', '"20 deg"'), "inputs.leg_offset.half_width", "expected a quantity in m"),
    (('"uniform"', '"triangular"'), "inputs.leg_offset", "distribution 'triangular' is not one of"),
    (('focus = "10 um"', 'focus = "10 deg"'), "targets.focus", "expected a quantity in m"),
    (('focus =', 'defocus ='), "targets.defocus", "did you mean 'focus'"),
    (('["60 deg", "60 deg"]', '["60 deg", "95 deg"]'), "workspace.elevation", "within [0 deg, 90 deg]"),
    (('elevation = ["60 deg", "60 deg"]', 'z = ["1 mm", "-1 mm"]'), "workspace.z", "is above high"),
    (("sobol_samples = 1024", "sobol_samples = 1000"), "sobol_samples", "power of 2"),
    (("samples = 20000", "samples = 2.5"), "samples", "expected an integer"),
])
def test_bad_files_are_named(change, key, problem):
    with pytest.raises(bg.BudgetError) as caught:
        bg.parse(SMALL.replace(*change), "small.toml")
    assert f"small.toml: {key}: " in str(caught.value) and problem in str(caught.value)


def test_every_problem_is_told_and_missing_tables_named():
    text = SMALL.replace("leg_offset =", "leg_ofset =").replace('focus =', 'defocus =')
    with pytest.raises(bg.BudgetError) as caught:
        bg.parse(text, "two.toml")
    assert len(caught.value.problems) == 2
    with pytest.raises(bg.BudgetError, match="targets: missing"):
        bg.parse(SMALL.split("[targets]")[0], "x.toml")
    with pytest.raises(bg.BudgetError, match="no uncertain input"):
        bg.parse(SMALL.replace('"20 um"', '"0 um"').replace('sd = "10 um"', 'sd = "0 um"')
                 .replace('"0.1 mm"', '"0 mm"'))
    with pytest.raises(bg.BudgetError, match="nope.toml: file: does not exist"):
        bg.load("nope.toml")


def _brute_ranks(n, p, tail=0.025):
    """The ranks (r, s) by trying every pair: the coverage P(r <= K <= s - 1), K ~ Binomial(n, p),
    summed from the probability mass function term by term, not from a cdf."""
    pmf = [binom.pmf(k, n, p) for k in range(n + 1)]
    below = lambda r: sum(pmf[:r])            # P(K <= r - 1)
    r = max(r for r in range(n + 1) if below(r) <= tail + 1e-15)
    s = min([s for s in range(1, n + 1) if 1 - below(s) <= tail + 1e-15] or [n + 1])
    return r, s, below(s) - below(r)


@pytest.mark.parametrize("n, p", [(200, 0.9), (59, 0.95), (1500, 0.997), (40, 0.5), (1227, 0.997)])
def test_interval_ranks_are_the_binomial_s(n, p):
    r, s, coverage = bg.ranks(n, p)
    assert (r, s) == _brute_ranks(n, p)[:2] and coverage == pytest.approx(_brute_ranks(n, p)[2], abs=1e-9)
    assert s > n or coverage >= 0.95      # a 90 % interval labelled 95 % fails here


def test_needed_samples_is_where_the_sample_maximum_first_bounds_the_quantile():
    # P(max of n < x_p) = p^n must be at most 2.5 %: for 0.9999, n = ln 0.025 / ln 0.9999 = 36,887
    for p in (0.9, 0.997, 0.9999):
        n = bg.needed_samples(p)
        assert p ** n <= 0.025 < p ** (n - 1)
        assert bg.ranks(n, p)[1] <= n and bg.ranks(n - 1, p)[1] == n   # n - 1 samples: no upper end
    assert bg.needed_samples(0.9999) == 36_887 and bg.needed_samples(0.997) == 1228


def test_quantile_interval_covers_a_uniform_s_known_quantile_as_often_as_it_says():
    """U(0, 1)'s 99.7 % quantile is 0.997: 1,500 sets of 2,000 draws; the interval holds it in
    the share of sets its exact coverage says (0.96 here; a 90 % interval would give ~0.90, 9
    standard errors away); the estimate (linear interpolation at rank 1 + (n - 1) p) averages
    E[U(k)] = k / (n + 1) there, (1 + 1999 * 0.997) / 2001, within 5 standard errors (3e-5 each)."""
    rng = np.random.default_rng(1)
    found = [bg.quantile(rng.random(2000), 0.997) for _ in range(1500)]
    coverage = found[0][3]
    covered = np.mean([lo <= 0.997 <= hi for _, lo, hi, _ in found])
    assert coverage >= 0.95 and abs(covered - coverage) < 3 * np.sqrt(coverage * (1 - coverage) / 1500)
    assert abs(np.mean([v for v, *_ in found]) - (1 + 1999 * 0.997) / 2001) < 1.5e-4


def test_percent_keeps_the_digits():
    assert bg.percent(0.9999) == "99.99 %" and bg.percent(0.997) == "99.7 %" and bg.percent(0.99999) == "99.999 %"
    assert bg.percent(0.5) == "50 %"


def test_quantiles_and_sobol_against_the_first_order_model():
    """One pose, one elevation, small tolerances (a near-linear map): the focus quantile is that
    of the analytic sensitivity's linear model sampled apart, and the group Sobol indices of dz are
    the groups' shares of its first-order variance."""
    budget = bg.parse(SMALL)
    params = StewartParams.paper()
    result = bg.run_budget(budget, progress=False, allocation=False)
    gradient = tl.sensitivity(params, params.home_pose, np.radians(60))[2]
    rng = np.random.default_rng(9)
    draws = np.zeros((400_000, tl.N_INPUTS))
    for k, dist in enumerate(budget.inputs):
        if dist is not None:
            draws[:, k] = dist.ppf(rng.random(len(draws)))
    focus = result["quantiles"]["focus"]
    assert np.quantile(np.abs(draws @ gradient), 0.997) == pytest.approx(focus["value"], rel=0.03)
    assert focus["low"] < focus["value"] < focus["high"] and focus["met"] == (focus["high"] < 1e-5)
    sobol = result["sobol"]
    z = sobol["components"].index("z")
    variances = np.array([0.0 if d is None else d.std ** 2 for d in budget.inputs]) * gradient ** 2
    shares = [variances[list(tl.GROUPS[g])].sum() / variances.sum() for g in sobol["groups"]]
    assert np.abs(np.array(sobol["first"][z]) - shares).max() < 0.05
    assert max(sobol["first_conf"][z]) < 0.1
    assert result["leading_inputs"]["focus"][0][0] == "base_joint_2_z"
    assert result["linear_shares"]["z"] == pytest.approx(dict(zip(sobol["groups"], shares)), abs=0.01)


def test_allocation_meets_the_targets_for_less_than_a_plain_scaling():
    """The allocated tolerances meet each target at 99.7 % in a fresh Monte Carlo (other draws),
    and cost less than scaling every group alike until the same targets are met (which tightens
    the encoder scale, whose error hardly shows at home, as much as the rest)."""
    budget = bg.parse(SMALL.replace("[workspace]", 'leg_scale = { distribution = "uniform", half_width = 1e-4 }\n'
                                                   '[workspace]'))
    params = StewartParams.paper()
    found = bg.allocate(params, budget, seed=3, samples=20000, verify=20000)
    scales = {g: v["scale"] for g, v in found["groups"].items()}
    check, _ = bg.monte_carlo(params, budget, 40000, seed=123, scales=scales)
    assert found["verified"] and all(c["value"] < c["target"] for c in check.values())
    assert any(c["value"] > 0.8 * c["target"] for c in check.values())   # not tightened far beyond need
    def plain_meets(s):
        return all(c["value"] < c["target"] for c in
                   bg.monte_carlo(params, budget, 20000, 5, scales=dict.fromkeys(scales, s))[0].values())
    low, high = 0.0, 1.0   # bisection for the largest common scale that meets the targets
    for _ in range(8):
        low, high = ((low + high) / 2, high) if plain_meets((low + high) / 2) else (low, (low + high) / 2)
    assert found["cost"] < len(scales) / high


def test_a_list_of_poses_is_drawn_from_evenly():
    """`poses` instead of ranges: every commanded pose is home plus one of them, each drawn about
    as often; giving both is refused."""
    listed = 'poses = [["10 mm", 0, 0, 0, 0, 0], [0, "-5 mm", 0, 0, "0.1 deg", 0]]\n'
    budget = bg.parse(SMALL.replace("[workspace]\n", "[workspace]\n" + listed))
    _, poses, elevation = bg._map(budget, np.random.default_rng(2).random((4000, bg._dimensions(budget))))
    travel = poses - StewartParams.paper().home_pose
    first = np.all(np.isclose(travel, [0.01, 0, 0, 0, 0, 0]), axis=1)
    second = np.all(np.isclose(travel, [0, -0.005, 0, 0, np.radians(0.1), 0]), axis=1)
    assert np.all(first | second) and 0.45 < first.mean() < 0.55 and np.all(elevation == np.radians(60))
    with pytest.raises(bg.BudgetError, match="workspace.poses: give either ranges"):
        bg.parse(SMALL.replace("[workspace]\n", '[workspace]\n' + listed + 'x = ["-1 mm", "1 mm"]\n'))


def test_met_is_judged_on_the_interval_s_upper_end():
    """A target between the quantile and its interval's upper end is not met; just above that
    end it is (the same draws: the seed is the budget's)."""
    budget = bg.parse(SMALL)
    params = StewartParams.paper()
    found, _ = bg.monte_carlo(params, budget, 5000, seed=2)
    focus = found["focus"]
    assert focus["value"] < focus["high"]
    inside = dataclasses.replace(budget, targets={"focus": (focus["value"] + focus["high"]) / 2})
    assert not bg.monte_carlo(params, inside, 5000, seed=2)[0]["focus"]["met"]
    above = dataclasses.replace(budget, targets={"focus": focus["high"] * (1 + 1e-9)})
    assert bg.monte_carlo(params, above, 5000, seed=2)[0]["focus"]["met"]


@pytest.mark.parametrize("samples, error, text", [
    (0, bg.BudgetError, "samples: 0 samples cannot bound the 99.7 % quantile from above: its 95 % interval needs "
                        "at least 1,228"),
    (-5, bg.BudgetError, "samples: -5 samples cannot bound"),
    (True, TypeError, "samples must be an integer (the number of Monte Carlo draws), not bool True"),
    ("2000", TypeError, "samples must be an integer (the number of Monte Carlo draws), not str '2000': write 2000"),
    (2e3, TypeError, "not float 2000.0: write 2000"),
    (10 ** 9, bg.BudgetError, "samples: 1,000,000,000 samples is more than the 100,000,000 a budget takes"),
])
def test_bad_sample_counts_are_refused_naming_samples_before_anything_runs(samples, error, text):
    with pytest.raises(error) as caught:
        bg.run_budget(bg.parse(SMALL, "small.toml"), samples=samples, progress=False)
    assert text in str(caught.value)


def test_numpy_integers_are_sample_counts_and_the_result_is_json():
    result = bg.run_budget(bg.parse(SMALL), samples=np.int64(2000), progress=False, sobol_samples=0,
                           allocation=False)
    assert result["samples"] == 2000 and type(result["samples"]) is int
    assert json.loads(json.dumps(result))["quantiles"]["focus"]["coverage"] == pytest.approx(bg.ranks(2000, 0.997)[2])


def test_a_file_too_small_for_its_probability_is_refused_saying_what_it_needs():
    with pytest.raises(bg.BudgetError, match=r"small.toml: samples: 20,000 samples cannot bound the 99.99 % quantile"
                                             r".*at least 36,887"):
        bg.parse(SMALL.replace("seed = 4", "seed = 4\nprobability = 0.9999"), "small.toml")


def test_a_budget_beyond_memory_is_refused_with_its_estimate(monkeypatch):
    monkeypatch.setattr(resources, "available_memory", lambda: 100e6)
    with pytest.raises(resources.ResourceError, match=r"budget small: .* pose errors, ~.* of memory; 100 MB is "
                                                      r"available: lower samples \(at most ~625,000 here\)"):
        bg.run_budget(bg.parse(SMALL), samples=10 ** 6, progress=False)


def test_the_cost_counts_every_pose_error():
    """SMALL: 2 groups, no varying workspace: Saltelli n (2 + 2) = 4,096 Sobol evaluations, the
    allocation 10^5 draws of each group's own error plus a check of the Monte Carlo's size."""
    cost = bg.estimate(StewartParams.paper(), bg.parse(SMALL), 20_000, 1024)
    assert cost.evaluations == 20_000 + 1024 * 4 + 2 * 100_000 + 20_000
    assert cost.memory == 2 * 100_000 * 96 and cost.seconds > 0
    assert bg.estimate(StewartParams.paper(), bg.parse(SMALL), 10 ** 6, 0, False).memory == 160e6


def test_the_cost_is_told_before_the_run(capsys):
    bg.run_budget(bg.parse(SMALL), samples=2000, progress=True, sobol_samples=0, allocation=False)
    told = capsys.readouterr().err
    assert "budget small: 2,000 pose errors, ~" in told and " of them on one core (the Sobol bootstrap" in told


@pytest.mark.parametrize("line, key, named", [
    ('leg_offset = { distribution = "uniform", half_width = "5 m" }', "inputs.leg_offset", "leg_offset_1 = 5 m"),
    ('base_clearance = { distribution = "normal", sd = "1 m" }', "inputs.base_clearance",
     "base_clearance_1 alone at its 7.03 sd extreme (base_clearance_1 = 7.03 m)"),
])
def test_an_unreachable_tolerance_is_refused_naming_the_input_and_the_pose(line, key, named):
    text = SMALL.replace('leg_offset = { distribution = "uniform", half_width = "20 um" }', line)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", bg.BudgetWarning)
        budget = bg.parse(text, "far.toml")
    with pytest.raises(bg.BudgetError) as caught:
        bg.run_budget(budget, progress=False)
    said = str(caught.value)
    assert said.startswith(f"far.toml: {key}: ") and named in said
    assert "commanded travel [0, 0, 0] mm, [0, 0, 0] deg (x, y, z, roll, pitch, yaw) about home at elevation 60 deg" \
        in said


def test_a_bare_tolerance_beyond_a_hexapod_s_class_warns():
    with pytest.warns(bg.BudgetWarning, match=r"inputs.leg_offset: half_width = 0.05 is read as 0.05 m = 50 mm, "
                                              r".*if you meant 0.05 mm, write \"0.05 mm\""):
        bg.parse(SMALL.replace('"20 um"', "0.05"))
    with warnings.catch_warnings():
        warnings.simplefilter("error", bg.BudgetWarning)
        bg.parse(SMALL.replace('"20 um"', '"1.5 mm"'))       # within the class: no warning
        bg.parse(SMALL)


def test_the_result_file_is_written_whole_or_not_at_all(tmp_path, monkeypatch):
    budget = bg.parse(SMALL)
    bg.run_budget(budget, samples=2000, out=tmp_path, progress=False, sobol_samples=0, allocation=False)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    assert sorted(before) == ["small.json", "small.md", "small_quantiles.png"]
    def full(fd):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(atomic.os, "fsync", full)
    with pytest.raises(OSError, match="No space left"):
        bg.run_budget(budget, samples=3000, out=tmp_path, progress=False, sobol_samples=0, allocation=False)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before   # no torn file, no temporary
    assert json.loads(before["small.json"])["samples"] == 2000


def test_one_input_s_linear_share_is_its_own_variance():
    """A clearance's play |d| of d uniform in +-t has variance t^2/12 (not the deviation's t^2/3):
    with one leg offset (uniform +-h) and one base clearance (+-t) at one pose, the clearance's
    share of dz's first-order variance is c^2 t^2/12 / (c^2 t^2/12 + o^2 h^2/3) (c, o: their
    sensitivities), and the nonlinear pose errors of each input alone give the same shares."""
    text = SMALL.replace('leg_offset = { distribution = "uniform", half_width = "20 um" }',
                         'leg_offset_1 = { distribution = "uniform", half_width = "20 um" }').replace(
        'base_joint = { distribution = "normal", sd = "10 um" }\nbase_joint_2_z = { distribution = "uniform", '
        'half_width = "0.1 mm" }', 'base_clearance_1 = { distribution = "uniform", half_width = "30 um" }')
    budget = bg.parse(text)
    params = StewartParams.paper()
    leading, _ = bg.linear_shares(params, budget, poses=1)
    shares = dict(leading["focus"])
    k_offset, k_play = tl.INPUT_NAMES.index("leg_offset_1"), tl.INPUT_NAMES.index("base_clearance_1")
    pose, elevation = bg._map(budget, np.random.default_rng(budget.seed + 1).random((1, bg._dimensions(budget))))[1:]
    c = tl.sensitivity(params, pose[0], elevation[0])[2]
    play, offset = c[k_play] ** 2 * 30e-6 ** 2 / 12, c[k_offset] ** 2 * 20e-6 ** 2 / 3
    assert shares["base_clearance_1"] == pytest.approx(play / (play + offset), rel=1e-9)
    draws = np.random.default_rng(3).uniform(-1, 1, 200_000)
    alone = {}
    for k, scale in ((k_offset, 20e-6), (k_play, 30e-6)):
        samples = np.zeros((len(draws), tl.N_INPUTS))
        samples[:, k] = scale * draws
        alone[k] = tl.pose_errors(params, pose[0], samples, elevation[0])[:, 2].var()
    assert shares["base_clearance_1"] == pytest.approx(alone[k_play] / (alone[k_play] + alone[k_offset]), rel=0.02)
    assert tl.uniform_variances(tl.geometric_inputs(base_clearance=3e-5))[k_play] == pytest.approx(3e-5 ** 2 / 12)
    assert tl.uniform_variances(tl.geometric_inputs(leg_offset=2e-5))[k_offset] == pytest.approx(2e-5 ** 2 / 3)

"""Geometric tolerance budgets: a budget file (scenarios/budgets/*.toml) read, sampled and judged.

A budget file names the hexapod's uncertain geometric inputs (plant.hexapod.tolerance's groups
and members, each a distribution of scenarios.spec.distributions), the workspace (commanded
poses as travel about home, and the telescope's elevation range), the targets on the pose error
and the probability they must hold with. ``run_budget`` answers with:

* Monte Carlo: each target's metric at the probability's quantile, with its exact 95 %
  distribution-free interval (order statistics whose ranks the binomial distribution gives;
  ``quantile``), over samples spread on the workspace and the elevation range; a target is
  met when the interval's upper end is under it, so a sample count too small to bound the
  quantile from above (``needed_samples``) is refused, with the count it needs;
* Sobol indices (SALib, Saltelli) of each metric by input group, the workspace a group of its
  own, with bootstrap intervals; and the inputs with the largest first-order (linear) variance;
* an allocation: per-group scale factors of the tolerances that meet every target at the
  probability for the least cost under the ASSUMED cost model cost_g = weight_g / scale_g
  (tightening a group's tolerances by a factor s costs 1/s times as much), checked by a fresh
  Monte Carlo run whose quantile's upper 95 % bound must be under each target.

Before anything runs: the samples asked for are checked (an integer, enough for the
probability, within what memory holds) and the cost is estimated (``estimate``); each input at
its extreme, alone, at the workspace's corners, must leave the legs a pose (``check_reach``),
else the input and the pose are named; a tolerance far beyond a hexapod's class warns
(``BudgetWarning``: a bare 0.05 is 50 mm). The result file is written whole or not at all.

It lives with the runs (not in scenarios.spec) because, like a campaign, it is a file that is
read and run: the parsing errors are ScenarioErrors naming file, key and problem, the math
stays in plant.hexapod.tolerance. No co-simulation runs: the dynamic budget (payload and sensor
calibration inputs, on Dask) is the campaigns'.
"""
import itertools
import math
import numbers
import pathlib
import sys
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import binom
from tqdm import tqdm

from plant.errors import UnreachablePoseError
from plant.hexapod import tolerance as tl
from plant.hexapod.model import StewartParams
from scenarios import spec
from scenarios.output import budget_report
from scenarios.output.budget_report import percent
from scenarios.runs import estimates as resources
from scenarios.spec import distributions
from scenarios.spec.units import UnitError, to_si

SHIPPED = pathlib.Path(__file__).resolve().parents[1] / "budgets"
POSE_KEYS = tl.POSE_NAMES
# metric -> (what it measures, its SI unit, its value from pose errors (n, 6))
METRICS = {
    "focus": ("|dz|, the pose error along the optical axis (defocus)", "m", lambda e: np.abs(e[:, 2])),
    "lateral": ("|(dx, dy)|, the lateral position error", "m", lambda e: np.hypot(e[:, 0], e[:, 1])),
    "position": ("|(dx, dy, dz)|, the position error a metrology system measures", "m",
                 lambda e: np.linalg.norm(e[:, :3], axis=1)),
    "tilt": ("|(droll, dpitch)|, the tilt error", "rad", lambda e: np.hypot(e[:, 3], e[:, 4])),
}
_TOP = ("name", "samples", "seed", "probability", "sobol_samples", "allocation_samples", "inputs", "workspace",
        "targets", "cost")
_MEMBERS = {name: (group, k) for group, columns in tl.GROUPS.items() for k in columns
            for name in [tl.INPUT_NAMES[k]]}
READS = {"focus": [2], "lateral": [0, 1], "position": [0, 1, 2], "tilt": [3, 4]}   # metric -> components
WORKSPACE_GROUP = "workspace"
CONFIDENCE = 0.95
ALLOCATION_SAMPLES = 100_000   # samples of each group's own error the allocation scales
MAX_SAMPLES = 10 ** 8          # Monte Carlo draws: the file's limit and the argument's
BYTES_PER_SAMPLE = 160         # peak memory per Monte Carlo draw: its pose error (48 B), the chunks it is
                               # joined from (48 B), a metric's values and their sorted copy (16 B each)
# ASSUMED: the class of a hexapod's geometric tolerances (joints 0.2 mm, the kit's defaults): ten
# times that is no tolerance but a misread unit (a bare 0.05 is 50 mm); SI per unit of the inputs
PLAUSIBLE = {"m": 2e-3, "1": 1e-2}
NORMAL_EXTREME = 7.03          # a normal draw's extreme: _map clips u to [1e-12, 1 - 1e-12], ndtri(1e-12) = -7.03


class BudgetError(spec.ScenarioError):
    """Problems in a budget file; the message says file, key and problem, one line each."""


class BudgetWarning(UserWarning):
    """A budget that runs but is likely not what was meant (a tolerance beyond a hexapod's class)."""


@dataclass(frozen=True)
class Budget:
    """A budget file, read: SI values throughout."""

    name: str
    source: str
    inputs: tuple                  # (66,) Distribution or None (not uncertain), INPUT_NAMES' order
    low: np.ndarray                # (6,) workspace: lowest travel about home [m, rad]
    high: np.ndarray               # (6,) highest travel
    poses: np.ndarray              # (m, 6) or (0, 6): a list of travels, chosen uniformly, instead
    elevation: tuple               # (lowest, highest) [rad]
    targets: dict                  # metric -> limit [SI]
    probability: float
    samples: int
    sobol_samples: int
    seed: int
    allocation_samples: int = ALLOCATION_SAMPLES
    cost: dict = field(default_factory=dict)   # group -> weight (ASSUMED cost model), 1 when not given
    keys: tuple = ()               # (66,) the file's key that set each input ("inputs.<group or member>")

    @property
    def groups(self):
        """The groups with an uncertain member, in GROUPS' order."""
        return tuple(g for g, cols in tl.GROUPS.items() if any(self.inputs[k] is not None for k in cols))


def _number(source, key, value, kind=float, low=None, high=None):
    if isinstance(value, bool) or not isinstance(value, (int, float) if kind is float else int):
        raise BudgetError(source, key, f"expected {'a number' if kind is float else 'an integer'}, got {value!r}")
    if (low is not None and not value >= low) or (high is not None and not value <= high) or not math.isfinite(value):
        raise BudgetError(source, key, f"must lie in [{low}, {high}], got {value!r}")
    return kind(value)


def _quantity(source, key, value, dimension):
    try:
        return to_si(value, dimension)
    except UnitError as exc:
        raise BudgetError(source, key, str(exc)) from None


def _range(source, key, value, dimension):
    if not (isinstance(value, list) and len(value) == 2):
        raise BudgetError(source, key, f"expected [low, high] (e.g. [\"-10 mm\", \"10 mm\"]), got {value!r}")
    low, high = (_quantity(source, f"{key}[{i}]", v, dimension) for i, v in enumerate(value))
    if not low <= high:
        raise BudgetError(source, key, f"low {value[0]!r} is above high {value[1]!r}")
    return low, high


def _inputs(source, table):
    found, keys = [None] * tl.N_INPUTS, [""] * tl.N_INPUTS
    problems = spec.Problems(BudgetError)
    for key, problem in spec.unknown_keys(set(table) - set(tl.GROUPS) - set(_MEMBERS),
                                          list(tl.GROUPS) + ["<group>_<leg>[_<x|y|z>]"]):
        problems.errors.append(BudgetError(source, f"inputs.{key}", problem))
    # a group first, then its members: a member's own line wins whatever the file's order
    for key in sorted(table, key=lambda k: k in _MEMBERS):
        with problems.part():
            if key in tl.GROUPS:
                dist = distributions.parse(source, f"inputs.{key}", table[key], tl.UNITS[key], BudgetError)
                for k in tl.GROUPS[key]:
                    found[k], keys[k] = dist, f"inputs.{key}"
                _plausible(source, key, table[key], dist)
            elif key in _MEMBERS:
                group, k = _MEMBERS[key]
                found[k] = distributions.parse(source, f"inputs.{key}", table[key], tl.UNITS[group], BudgetError)
                keys[k] = f"inputs.{key}"
                _plausible(source, key, table[key], found[k])
    problems.raise_any()
    found = [None if d is None or d.scale == 0 else d for d in found]
    if all(d is None for d in found):
        raise BudgetError(source, "inputs", "no uncertain input: give at least one group or member a scale > 0")
    return tuple(found), tuple(keys)


def _plausible(source, key, table, dist):
    """A BudgetWarning when ``dist``'s scale is beyond a hexapod's tolerances (PLAUSIBLE)."""
    unit = tl.UNITS[key if key in tl.GROUPS else _MEMBERS[key][0]]
    if dist.scale <= PLAUSIBLE[unit]:
        return
    written = table.get(distributions.SCALES[dist.kind]) if isinstance(table, dict) else None
    bare = isinstance(written, (int, float)) or (isinstance(written, str) and not written.strip(" .0123456789eE+-"))
    read = (f"{dist.scale:g} m = {dist.scale * 1e3:g} mm" if unit == "m"
            else f"{dist.scale:g} ({dist.scale * 1e6:g} ppm)")
    said = f"{distributions.SCALES[dist.kind]} = {written!r} is read as {read}"
    hint = (f"; a bare number is SI: if you meant {written} mm, write \"{written} mm\"" if bare and unit == "m" else "")
    warnings.warn(BudgetWarning(f"{spec.text.shown(source)}: inputs.{key}: {said}, beyond a hexapod's geometric "
                                f"tolerances (at most {PLAUSIBLE[unit]:g} {unit} is plausible){hint}"), stacklevel=2)


def _workspace(source, table):
    allowed = POSE_KEYS + ("poses", "elevation")
    problems = spec.Problems(BudgetError)
    for key, problem in spec.unknown_keys(set(table) - set(allowed), allowed):
        problems.errors.append(BudgetError(source, f"workspace.{key}", problem))
    problems.raise_any()
    low, high = np.zeros(6), np.zeros(6)
    for j, key in enumerate(POSE_KEYS):
        if key in table:
            low[j], high[j] = _range(source, f"workspace.{key}", table[key], tl.POSE_UNITS[j])
    poses = np.zeros((0, 6))
    if "poses" in table:
        if any(k in table for k in POSE_KEYS):
            raise BudgetError(source, "workspace.poses", "give either ranges (x, y, ...) or a list of poses, not both")
        rows = table["poses"]
        if not isinstance(rows, list) or not rows or any(not isinstance(r, list) or len(r) != 6 for r in rows):
            raise BudgetError(source, "workspace.poses", "expected a list of poses, each 6 values [x, y, z, roll, "
                                                         "pitch, yaw] of travel about home")
        poses = np.array([[_quantity(source, f"workspace.poses[{i}][{j}]", v, tl.POSE_UNITS[j])
                           for j, v in enumerate(row)] for i, row in enumerate(rows)])
    elevation = _range(source, "workspace.elevation", table.get("elevation", ["90 deg", "90 deg"]), "rad")
    if elevation[0] < -1e-12 or elevation[1] > np.pi / 2 + 1e-12:
        raise BudgetError(source, "workspace.elevation", "must lie within [0 deg, 90 deg]")
    return low, high, poses, (max(elevation[0], 0.0), min(elevation[1], np.pi / 2))


def _targets(source, table):
    if not isinstance(table, dict) or not table:
        raise BudgetError(source, "targets", f"expected a table of limits, e.g. focus = \"10 um\"; metrics: "
                                             f"{', '.join(METRICS)}")
    problems = spec.Problems(BudgetError)
    for key, problem in spec.unknown_keys(set(table) - set(METRICS), METRICS):
        problems.errors.append(BudgetError(source, f"targets.{key}", problem))
    problems.raise_any()
    out = {}
    for key, value in table.items():
        out[key] = _quantity(source, f"targets.{key}", value, METRICS[key][1])
        if not out[key] > 0:
            raise BudgetError(source, f"targets.{key}", f"must be > 0, got {value!r}")
    return out


def parse(text, source="<string>"):
    """The Budget of TOML ``text``; BudgetError naming file, key and problem (all found)."""
    data = spec.read_toml(text, source, BudgetError)
    problems = spec.Problems(BudgetError)
    for key, problem in spec.unknown_keys(set(data) - set(_TOP), _TOP):
        problems.errors.append(BudgetError(source, key, problem))
    for key in ("inputs", "workspace", "targets"):
        if not isinstance(data.get(key), dict):
            problems.errors.append(BudgetError(source, key, f"missing: a budget needs an [{key}] table"))
    problems.raise_any()
    values = {}
    with problems.part():
        values["inputs"], values["keys"] = _inputs(source, data["inputs"])
    with problems.part():
        values["workspace"] = _workspace(source, data["workspace"])
    with problems.part():
        values["targets"] = _targets(source, data["targets"])
    with problems.part():
        values["name"] = spec.check_name(source, "name", data.get("name", pathlib.Path(source).stem), BudgetError)
        values["probability"] = _number(source, "probability", data.get("probability", 0.997), float, 0.5, 0.99999)
        values["samples"] = _number(source, "samples", data.get("samples", 1_000_000), int, 1000, MAX_SAMPLES)
        values["seed"] = _number(source, "seed", data.get("seed", 0), int, 0, 2 ** 32 - 1)
        n = _number(source, "sobol_samples", data.get("sobol_samples", 8192), int, 0, 2 ** 20)
        if n and n & (n - 1):
            raise BudgetError(source, "sobol_samples", f"must be a power of 2 (Saltelli's sampling) or 0, got {n}")
        values["sobol_samples"] = n
        values["allocation_samples"] = _number(source, "allocation_samples",
                                               data.get("allocation_samples", ALLOCATION_SAMPLES), int, 1000, 10 ** 7)
    with problems.part():
        cost = data.get("cost", {})
        if not isinstance(cost, dict):
            raise BudgetError(source, "cost", f"expected a table of weights per group, got {cost!r}")
        for key, problem in spec.unknown_keys(set(cost) - set(tl.GROUPS), tl.GROUPS):
            raise BudgetError(source, f"cost.{key}", problem)
        values["cost"] = {g: _number(source, f"cost.{g}", w, float, 1e-9, 1e9) for g, w in cost.items()}
    with problems.part():
        if "samples" in values:
            check_samples(values["samples"], values["probability"], source, "samples")
    problems.raise_any()
    low, high, poses, elevation = values["workspace"]
    return Budget(values["name"], source, values["inputs"], low, high, poses, elevation, values["targets"],
                  values["probability"], values["samples"], values["sobol_samples"], values["seed"],
                  values["allocation_samples"], values["cost"], values["keys"])


def load(path):
    """A budget file, or the name of a shipped one (scenarios/budgets/<name>.toml)."""
    path = spec.text.shipped_file(path, SHIPPED, BudgetError, "budget")
    return parse(spec.read_text(path, BudgetError, "budget"), str(path))


# ------------------------------------------------------------------------------ sampling
def _workspace_dims(budget):
    """The names of the workspace's varying dimensions ("pose" for a list of poses, coordinates
    of ranges, "elevation"): one unit-cube column each, after the inputs'."""
    if len(budget.poses):
        names = ["pose"] if len(budget.poses) > 1 else []
    else:
        names = [k for j, k in enumerate(POSE_KEYS) if budget.high[j] > budget.low[j]]
    return names + (["elevation"] if budget.elevation[1] > budget.elevation[0] else [])


def _map(budget, u, scales=None):
    """(samples (n, 66), commanded poses (n, 6), elevations (n,)) of unit-cube points ``u``
    (n, k): one column per uncertain input (INPUT_NAMES' order), then one per varying
    workspace dimension (``_workspace_dims``). ``scales``: a factor per group (allocation)."""
    columns = np.zeros((tl.N_INPUTS, len(u)))   # filled a row at a time, then laid out (n, 66)
    col = 0
    for k, dist in enumerate(budget.inputs):
        if dist is not None:
            x = u[:, col] if dist.kind == "uniform" else np.clip(u[:, col], 1e-12, 1 - 1e-12)   # ppf(0) = -inf
            columns[k] = dist.ppf(x)
            col += 1
    if scales is not None:
        for group, s in scales.items():
            columns[list(tl.GROUPS[group])] *= s
    samples = np.ascontiguousarray(columns.T)
    travel = np.zeros((len(u), 6))
    if len(budget.poses):
        travel[:] = budget.poses[0]
    else:
        travel[:] = budget.low   # the fixed coordinates; the varying ones are set below
    lo, hi = budget.elevation
    elevation = np.full(len(u), lo)
    for name in _workspace_dims(budget):
        if name == "pose":
            travel = budget.poses[np.minimum((u[:, col] * len(budget.poses)).astype(int), len(budget.poses) - 1)]
        elif name == "elevation":
            elevation = lo + (hi - lo) * u[:, col]
        else:
            j = POSE_KEYS.index(name)
            travel[:, j] = budget.low[j] + (budget.high[j] - budget.low[j]) * u[:, col]
        col += 1
    return samples, StewartParams.paper().home_pose + travel, elevation


def _errors(params, budget, u, bar=None, scales=None):
    """Pose errors (n, 6) of the unit-cube points ``u``: an array (n, k), or (seed, n, k) for
    ``_draws``; chunk by chunk (``bar`` advanced), ``scales`` as ``_map``'s."""
    chunks = _draws(*u) if isinstance(u, tuple) else (u[s:s + tl.CHUNK] for s in range(0, len(u), tl.CHUNK))
    out = []
    for points in chunks:
        samples, poses, elevation = _map(budget, points, scales)
        try:
            out.append(tl.pose_errors(params, poses, samples, elevation))
        except UnreachablePoseError as exc:   # inputs together beyond what check_reach tried alone
            raise _unreachable(budget, samples[exc.sample], poses[exc.sample], elevation[exc.sample],
                               "a draw of the inputs together") from None
        if bar is not None:
            bar.update(len(samples))
    return np.concatenate(out)


def _pose_text(pose, elevation):
    """A commanded pose as travel about home in mm and deg, and the elevation."""
    travel = pose - StewartParams.paper().home_pose
    mm, deg = (", ".join(f"{v:.4g}" for v in part) for part in (travel[:3] * 1e3, np.degrees(travel[3:])))
    return (f"travel [{mm}] mm, [{deg}] deg (x, y, z, roll, pitch, yaw) about home at elevation "
            f"{np.degrees(elevation):.4g} deg")


def _unreachable(budget, sample, pose, elevation, what):
    """The BudgetError of a sample (66,) whose legs cannot meet at ``pose``: its inputs with the
    largest deviations named, by the file's key."""
    largest = [k for k in np.argsort(-np.abs(sample))[:3] if sample[k] != 0]
    named = ", ".join(f"{tl.INPUT_NAMES[k]} = {sample[k]:.4g} {tl.UNITS[_MEMBERS[tl.INPUT_NAMES[k]][0]]}"
                      for k in largest)
    keys = list(dict.fromkeys(budget.keys[k] for k in largest if budget.keys)) or ["inputs"]
    return BudgetError(budget.source, ", ".join(keys), f"{what} ({named}) leaves the hexapod no pose at the commanded "
                       f"{_pose_text(pose, elevation)}: its legs cannot meet; a hexapod's geometric tolerances are "
                       "micrometres to tenths of a millimetre: check the value and its unit")


def _corners(budget):
    """Commanded poses (m, 6) and elevations (m,) at the workspace's corners (a list of poses:
    each, at most 64) and both ends of the elevation range."""
    if len(budget.poses):
        travel = budget.poses[:64]
    else:
        travel = np.array(list(itertools.product(*zip(budget.low, budget.high))))
        travel = np.unique(travel, axis=0)
    lo, hi = budget.elevation
    poses = np.concatenate([travel, travel]) + StewartParams.paper().home_pose
    return poses, np.repeat([lo, hi], len(travel))


def check_reach(params, budget):
    """Each uncertain input at its extreme (uniform: +-half_width; normal: +-7.03 sd, the
    largest a draw takes), the others nominal, at the workspace's corners: a BudgetError
    naming every input that leaves the legs no pose, and the pose, before anything runs."""
    poses, elevation = _corners(budget)
    problems = spec.Problems(BudgetError)
    for k, dist in enumerate(budget.inputs):
        if dist is None:
            continue
        extreme = dist.scale * (1.0 if dist.kind == "uniform" else NORMAL_EXTREME)
        for sign in (1.0, -1.0):
            samples = np.zeros((len(poses), tl.N_INPUTS))
            samples[:, k] = sign * extreme
            try:
                tl.pose_errors(params, poses, samples, elevation)
            except UnreachablePoseError as exc:
                bound = f"its {'half_width' if dist.kind == 'uniform' else '7.03 sd extreme'}"
                problems.errors.append(_unreachable(budget, samples[exc.sample], poses[exc.sample],
                                                    elevation[exc.sample], f"{tl.INPUT_NAMES[k]} alone at {bound}"))
                break
    if problems.errors:   # one line per group (its members break alike)
        seen, kept = set(), []
        for error in problems.errors:
            if error.problems[0][1] not in seen:
                seen.add(error.problems[0][1])
                kept.append(error)
        raise BudgetError.joined(kept)


@dataclass
class Cost:
    """What a budget run will take, counted before it starts."""

    evaluations: int               # pose errors computed (Monte Carlo, Sobol, allocation)
    seconds: float                 # on one core, at the rate measured on this budget
    memory: float                  # bytes at the peak (the Monte Carlo's draws)

    def text(self):
        return (f"{self.evaluations:,d} pose errors, ~{resources._duration(self.seconds)} of them on one core (the "
                f"Sobol bootstrap and the allocation's search add to it), ~{resources._size(self.memory)} of memory")


def estimate(params, budget, samples, n_sobol, allocation=True):
    """The Cost of a run: the evaluations counted, each at the rate a timed 2,000 draws of this
    budget give (the clearance's leg forces make a draw ~4x dearer)."""
    dims = _dimensions(budget)
    start = time.perf_counter()
    _errors(params, budget, (budget.seed + 99, 2000, dims))
    rate = (time.perf_counter() - start) / 2000
    sobol_evaluations = n_sobol * (len(budget.groups) + (1 if _workspace_dims(budget) else 0) + 2)
    alloc = (budget.allocation_samples * len(budget.groups) + samples) if allocation else 0
    evaluations = samples + sobol_evaluations + alloc
    memory = max(samples * BYTES_PER_SAMPLE, sobol_evaluations * 8 * (dims + 12),
                 budget.allocation_samples * len(budget.groups) * 96 if allocation else 0)
    return Cost(evaluations, evaluations * rate, memory)


def check_cost(cost, budget):
    """ResourceError for a run that cannot finish here (more memory than is available, or
    longer than estimates.REFUSE_SECONDS), saying what to lower."""
    memory = resources.available_memory()
    if memory is not None and cost.memory > memory:
        raise resources.ResourceError(f"budget {budget.name}: {cost.text()}; {resources._size(memory)} is available: "
                                      f"lower samples (at most ~{int(memory / BYTES_PER_SAMPLE):,d} here)")
    if cost.seconds > resources.REFUSE_SECONDS:
        raise resources.ResourceError(f"budget {budget.name}: {cost.text()}: it would not finish; lower samples, "
                                      "sobol_samples or allocation_samples")


def _draws(seed, n, dimensions):
    """The points of ``np.random.default_rng(seed).random((n, dimensions))``, CHUNK rows at a
    time (the generator's stream is the same; the whole array of 10^6 samples would be 0.6 GB)."""
    rng = np.random.default_rng(seed)
    for start in range(0, n, tl.CHUNK):
        yield rng.random((min(tl.CHUNK, n - start), dimensions))


def _dimensions(budget):
    """The number of unit-cube columns of a sample: the uncertain inputs and the workspace's."""
    return sum(d is not None for d in budget.inputs) + len(_workspace_dims(budget))


def needed_samples(probability, confidence=CONFIDENCE):
    """The fewest samples whose interval (``ranks``) has an upper end: the largest of n values
    lies above the ``probability`` quantile with probability 1 - p^n, which must reach the
    upper tail's 1 - (1 - confidence) / 2."""
    n = math.ceil(math.log((1 - confidence) / 2) / math.log(probability))
    return n + (binom.sf(n - 1, n, probability) > (1 - confidence) / 2)   # rounding at the edge


def ranks(n, probability, confidence=CONFIDENCE):
    """(r, s, coverage): the 1-based ranks of the order statistics X(r) <= x_p <= X(s) that
    hold the ``probability`` quantile x_p with at least ``confidence``, distribution-free:
    the count K of values below x_p is Binomial(n, p), X(r) <= x_p when K >= r and X(s) >= x_p
    when K <= s - 1, so the coverage is P(r <= K <= s - 1); each tail outside it at most
    (1 - confidence) / 2: r the largest with P(K <= r - 1) <= tail, s the smallest with
    P(K >= s) <= tail. r = 0: no lower end (too few values); s = n + 1: no upper end."""
    tail = (1 - confidence) / 2
    k = np.arange(n + 1)
    r = int(np.searchsorted(binom.cdf(k, n, probability), tail, side="right"))
    s = int(np.searchsorted(-binom.sf(k, n, probability), -tail, side="left")) + 1
    coverage = binom.cdf(s - 1, n, probability) - (binom.cdf(r - 1, n, probability) if r else 0.0)
    return r, s, float(coverage)


def quantile(values, probability, confidence=CONFIDENCE):
    """(the ``probability`` quantile of ``values`` (linear interpolation), the lower and upper
    end of its interval at ``confidence`` (``ranks``; -inf or inf where the values cannot bound
    it), the interval's exact coverage)."""
    ordered = np.sort(values)
    n = len(ordered)
    r, s, coverage = ranks(n, probability, confidence)
    return (float(np.quantile(ordered, probability)), float(ordered[r - 1]) if r else -math.inf,
            float(ordered[s - 1]) if s <= n else math.inf, coverage)


def check_samples(samples, probability, source="<argument>", key="samples"):
    """``samples`` as an int: any integer type (numpy's too); a bool, float or text is refused
    (TypeError), and so is a count below what the probability needs or above MAX_SAMPLES
    (BudgetError naming ``key``)."""
    if isinstance(samples, bool) or not isinstance(samples, numbers.Integral):
        hint = ""
        if isinstance(samples, (float, str)):
            with_number = _whole(samples)
            hint = f": write {with_number}" if with_number is not None else ""
        raise TypeError(f"{key} must be an integer (the number of Monte Carlo draws), not "
                        f"{type(samples).__name__} {samples!r}{hint}")
    samples, needed = int(samples), needed_samples(probability)
    if samples < needed:
        raise BudgetError(source, key, f"{samples:,d} samples cannot bound the {percent(probability)} quantile from "
                          f"above: its {percent(CONFIDENCE)} interval needs at least {needed:,d} (the largest of n "
                          f"draws lies above it with probability 1 - p^n); give more samples or a lower probability")
    if samples > MAX_SAMPLES:
        raise BudgetError(source, key, f"{samples:,d} samples is more than the {MAX_SAMPLES:,d} a budget takes "
                          f"(~{resources._size(samples * BYTES_PER_SAMPLE)} of memory)")
    return samples


def _whole(value):
    """The int a float or text names when it is a whole number (2e3, "2000"), else None."""
    try:
        number = float(value)
    except ValueError:
        return None
    return int(number) if math.isfinite(number) and number == int(number) else None


def monte_carlo(params, budget, samples, seed, bar=None, scales=None):
    """Each target's metric at the budget's probability: {metric: {value, low, high, target,
    met}} from ``samples`` draws, and the pose errors (n, 6)."""
    errors = _errors(params, budget, (seed, samples, _dimensions(budget)), bar, scales)
    found = {}
    for metric, limit in budget.targets.items():
        value, low, high, coverage = quantile(METRICS[metric][2](errors), budget.probability)
        found[metric] = dict(value=value, low=low, high=high, target=limit, met=bool(high < limit),
                             coverage=coverage)
    return found, errors


def _components(budget):
    """The pose error's components the targets read (indices into POSE_KEYS)."""
    return sorted({j for m in budget.targets for j in READS[m]})


def sobol(params, budget, n, seed, bar=None, resamples=200):
    """Sobol indices by input group (the workspace a group of its own), SALib, of each pose
    error component the targets read: the signed components, whose variance the inputs share
    out (a metric's |.| or norm would mix their signs into interactions)."""
    names, groups = [], []
    for k, dist in enumerate(budget.inputs):
        if dist is not None:
            names.append(tl.INPUT_NAMES[k])
            groups.append(next(g for g, cols in tl.GROUPS.items() if k in cols))
    for name in _workspace_dims(budget):
        names.append(f"workspace_{name}")
        groups.append(WORKSPACE_GROUP)
    components = _components(budget)
    found = tl.sobol_indices(lambda u: _errors(params, budget, u, bar)[:, components], names,
                             [(0.0, 1.0)] * len(names), n, seed, resamples, CONFIDENCE, groups)
    return dict(components=[POSE_KEYS[j] for j in components], groups=list(found.names),
                first=found.first.tolist(), first_conf=found.first_conf.tolist(), total=found.total.tolist(),
                total_conf=found.total_conf.tolist(), evaluations=found.evaluations, base_samples=n)


def linear_shares(params, budget, poses=16, count=8):
    """The first-order (analytic sensitivity) variance shares, averaged over ``poses`` points
    of the workspace: ({metric: [(input, share)] of its ``count`` largest inputs}, {component:
    {group: share}} for the components the targets read); a metric's variance is that of the
    components it reads. The Sobol indices' first-order truth for small tolerances."""
    u = np.random.default_rng(budget.seed + 1).random((poses, _dimensions(budget)))
    _, pose_list, elevation = _map(budget, u)
    variances = np.array([0.0 if d is None else d.std ** 2 for d in budget.inputs])
    for k in range(tl.CLEARANCE.start, tl.N_INPUTS):   # the play |deviation|: its variance
        d = budget.inputs[k]
        if d is not None:
            variances[k] = d.scale ** 2 / 12 if d.kind == "uniform" else d.scale ** 2 * (1 - 2 / np.pi)
    parts = np.mean([tl.sensitivity(params, p, e) ** 2 * variances for p, e in zip(pose_list, elevation)], axis=0)
    leading = {}
    for metric in budget.targets:
        share = parts[READS[metric]].sum(axis=0)
        share = share / share.sum()
        leading[metric] = [(tl.INPUT_NAMES[k], float(share[k])) for k in np.argsort(share)[::-1][:count]]
    groups = {POSE_KEYS[j]: {g: float(parts[j, list(tl.GROUPS[g])].sum() / parts[j].sum()) for g in budget.groups}
              for j in _components(budget)}
    return leading, groups


# ---------------------------------------------------------------------------- allocation
def _group_errors(params, budget, samples, seed, bar=None):
    """Each group's own pose error (g, n, 6) on one set of draws (the others at nominal)."""
    out = []
    for group in budget.groups:
        alone = {g: 0.0 for g in budget.groups if g != group}
        out.append(_errors(params, budget, (seed, samples, _dimensions(budget)), bar, alone))
    return np.array(out)


def allocate(params, budget, seed, bar=None, samples=None, verify=None):
    """Per-group scale factors s_g of the file's tolerances that meet every target at the
    probability for the least cost sum_g w_g / s_g (ASSUMED: tightening by s costs 1/s).

    To first order the pose error is the sum of the groups' own errors, so the metric of
    sum_g s_g e_g, on one set of draws of each group's own error, tells any candidate at once.
    Least cost under a variance limit sum_g s_g^2 V_g puts s_g proportional to (w_g / V_g)^(1/3)
    (Lagrange); that shape is taken per target (V_g the group's variance of what that target
    reads) and scaled by bisection until every target's quantile is met with a 1 % margin;
    the cheapest candidate wins. A fresh nonlinear Monte Carlo (``verify`` samples, default
    the budget's) checks it: its quantile's upper 95 % bound must be under each target; if
    not, the scales shrink by 2 % and are checked again (at most 10 times)."""
    samples = samples or budget.allocation_samples
    contributions = _group_errors(params, budget, samples, seed, bar)
    weights = np.array([budget.cost.get(g, 1.0) for g in budget.groups])

    def meets(scales, margin=0.99):
        errors = np.tensordot(scales, contributions, axes=1)
        return all(np.quantile(METRICS[m][2](errors), budget.probability) <= margin * limit
                   for m, limit in budget.targets.items())

    candidates = []
    for metric in budget.targets:
        variance = np.maximum((contributions[:, :, READS[metric]] ** 2).sum(axis=2).mean(axis=1), 1e-300)
        shape = (weights / variance) ** (1 / 3)
        low, high = 0.0, 1.0
        while meets(high * shape):   # grow until it fails, then bisect
            low, high = high, 2 * high
        for _ in range(50):
            mid = (low + high) / 2
            low, high = (mid, high) if meets(mid * shape) else (low, mid)
        candidates.append(low * shape)
    scales = min(candidates, key=lambda s: float(np.sum(weights / s)))
    for attempt in range(11):
        if attempt:
            scales = scales * 0.98
            if bar is not None:   # one more check than the bar was told of
                bar.total += verify or budget.samples
                bar.refresh()
        named = dict(zip(budget.groups, scales.tolist()))
        check, _ = monte_carlo(params, budget, verify or budget.samples, seed + 7 + attempt, bar, named)
        if all(c["met"] for c in check.values()):
            break
    groups = {g: dict(scale=s, weight=float(w), cost=float(w / s), extra_cost=float(w / s - w),
                      tolerance=[_scale_of(budget, g) * s, tl.UNITS[g]], given=[_scale_of(budget, g), tl.UNITS[g]])
              for g, s, w in zip(budget.groups, scales.tolist(), weights)}
    return dict(groups=groups, cost=float(np.sum(weights / scales)), cost_as_given=float(weights.sum()),
                check=check, verified=all(c["met"] for c in check.values()), samples=samples)


def _scale_of(budget, group):
    """The group's largest scale (half_width or sd) in the file [SI]."""
    return max(budget.inputs[k].scale for k in tl.GROUPS[group] if budget.inputs[k] is not None)


# --------------------------------------------------------------------------------- run
def run_budget(path, samples=None, out=None, progress=True, sobol_samples=None, allocation=True):
    """Run a budget file (or a parsed Budget): Monte Carlo quantiles, Sobol indices, the
    leading inputs and the allocation; written to ``out``/<name>.json, with its charts and a
    report (<name>.md, scenarios.output.budget_report) when ``out`` is given (each file whole
    or not at all). ``samples``/``sobol_samples`` override the file's. Everything is
    checked and the cost estimated (told on stderr with ``progress``) before anything runs.
    Returns the results as a dict."""
    budget = path if isinstance(path, Budget) else load(path)
    samples = budget.samples if samples is None else check_samples(samples, budget.probability, budget.source)
    n_sobol = budget.sobol_samples if sobol_samples is None else sobol_samples
    params = StewartParams.paper()
    check_reach(params, budget)
    cost = estimate(params, budget, samples, n_sobol, allocation)
    check_cost(cost, budget)
    if progress:
        print(f"budget {budget.name}: {cost.text()}", file=sys.stderr, flush=True)
    with tqdm(total=cost.evaluations, desc=f"budget {budget.name}", unit="sample",
              unit_scale=True, disable=not progress) as bar:
        found, errors = monte_carlo(params, budget, samples, budget.seed, bar)
        result = dict(name=budget.name, source=budget.source, probability=budget.probability, samples=samples,
                      confidence=CONFIDENCE, metrics={m: METRICS[m][0] for m in budget.targets}, quantiles=found,
                      mean_error=errors.mean(axis=0).tolist(), std_error=errors.std(axis=0).tolist())
        result["leading_inputs"], result["linear_shares"] = linear_shares(params, budget)
        if n_sobol:
            result["sobol"] = sobol(params, budget, n_sobol, budget.seed, bar)
        if allocation:
            result["allocation"] = allocate(params, budget, budget.seed + 1, bar, verify=samples)
    if out is not None:   # <name>.json, its charts and <name>.md
        budget_report.write(result, out)
    return result

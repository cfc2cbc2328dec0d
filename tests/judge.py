"""An independent judge of the kit's verdict on random scenes (issue 27): a generator of
valid scenes drawn from the shipped ones, and a verdict read from the records alone,
without scenarios/flags.py.

A scene: the realistic hexapod slew (ball-screw actuators with a 25 kN limit, leg
encoders) or the 3T mechanism; master and extrapolation; the controller's gains scaled
by 0.25-4 (log-uniform); the communication step 0.5-1.3x the kit's predicted limit (the
prediction only scales the draw, it judges nothing); the force limits scaled by 0.6-1 (hexapod) or 0.3-1 (3T);
for the hexapod, the start elevation 5-88 deg. Runs are short (the hexapod's from 3 s
to 6 s: settling and the slew's start; the 3T's first 1.5 s) and record every step.

The judge calls a run bad when, in its records:
* it stopped before its stop time, or a value is not finite;
* a force command sits at one of its limits (the controller's force_limit, the plant's
  actuator_force_limit, checked on the force the plant applies) on more than HELD of the
  rows;
* the oscillation grows: the largest second difference of the measured lengths over the
  last quarter of the run exceeds GROWN times that over the quarter before it, and is
  above FLOOR (a growth by itself; the reference's own changes are smooth);
and clean otherwise. The kit's verdict is "refused" (ScenarioError before running),
"flagged" (a run not ok) or "clean". A miss: the judge says bad, the kit clean. A false
alarm: the judge says clean, the kit refused or flagged it.
"""
import dataclasses
import math

import numpy as np

import movingbase
from movingbase.scenarios import flags, runner, spec

HELD = 0.02         # share of rows at a force limit above which a run is saturated
GROWN = 3.0         # growth of the oscillation from one quarter of the run to the last
FLOOR = {"hexapod": 1e-7, "3t": 1e-6}     # m: second differences below are the sensors' noise


@dataclasses.dataclass
class Scene:
    seed: int
    kind: str
    file: str
    set: dict
    step: float
    limit: float


def _grid(seconds):
    """A time as written in a scene, in whole tenths of a millisecond."""
    return f"{round(seconds * 1e4) / 10:g} ms"


def draw(seed):
    """A valid random Scene for ``seed``."""
    rng = np.random.default_rng(seed)
    kind = ("hexapod", "3t")[rng.integers(2)]
    gain = math.exp(rng.uniform(math.log(0.25), math.log(4.0)))
    master = ("jacobi", "gauss-seidel")[rng.integers(2)]
    extrapolation = ("none", "linear")[rng.integers(2)]
    if kind == "hexapod":
        file = "telescope_slew_realistic"
        base = {"controller.kp": 3726457.1097513568, "controller.ki": 37462432.89571941, "controller.kd": 169743.13840853807}
        given = {k: v * gain for k, v in base.items()}
        given.update({"plant.actuator_force_limit": f"{25 * rng.uniform(0.6, 1):.4g} kN",
                      "base.start_elevation": f"{rng.uniform(5, 60):.3g} deg",
                      "base.target_elevation": f"{rng.uniform(65, 88):.3g} deg",
                      "start_time": "3 s", "stop_time": "6 s",
                      "sweep": {"parameter": "controller.feedforward", "values": ["moving_base"]}})
    else:
        file = "mechanism3t_paper"
        base = {"controller.kp": 8.6e3, "controller.ki": 1.6e4, "controller.kd": 890.0}
        given = {k: v * gain for k, v in base.items()}
        given.update({"controller.force_limit": f"{1e3 * rng.uniform(0.3, 1):.4g} N", "stop_time": "1.5 s",
                      "sweep": {"parameter": "controller.feedforward", "values": ["on"]}})
    given.update({"master": master, "extrapolation": extrapolation})
    limit = _predicted(file, given) or 1e-3        # 0: no step is stable with these gains
    step = max(1e-4, round(rng.uniform(0.5, 1.3) * limit * 1e4) / 1e4)
    if kind == "hexapod":                           # the encoder's rate filter below the step's Nyquist frequency
        given["sensor.rate_cutoff"] = f"{min(100.0, 0.4 / step):.4g} Hz"
    start = spec_value(given.get("start_time", "0 s"))
    steps = max(40, round((spec_value(given["stop_time"]) - start) / step))
    given["stop_time"] = _grid(start + steps * step)     # a whole number of steps
    return Scene(seed, kind, file, given, step, limit)


def _predicted(file, given):
    """The kit's predicted step limit at 1 ms (only to scale the draw)."""
    scenario = movingbase.load_scenario(file, set={**given, "step": "1 ms"})
    prepared = runner.prepare_loaded(scenario)
    return flags.predict(*prepared).limit


def _with_step(scene):
    forces = {"hexapod": ["controller.leg_force", "plant.leg_force_actual", "plant.leg_length"],
              "3t": ["controller.slider_force", "plant.slider_position", "controller.reference_position"]}[scene.kind]
    return {**scene.set, "step": _grid(scene.step), "record": {"interval": _grid(scene.step), "variables": forces}}


def judge(scene, run):
    """'bad' (with why) or 'clean', from the records of ``run`` alone."""
    if run.status == "failed" or not np.isfinite(run.values).all():
        return "bad", "cut short or not finite"
    if scene.kind == "hexapod":
        limits = [("controller.leg_force", 50e3),
                  ("plant.leg_force_actual", spec_value(scene.set["plant.actuator_force_limit"]))]
    else:
        limits = [("controller.slider_force", spec_value(scene.set["controller.force_limit"]))]
    for name, limit in limits:
        held = float(np.mean(np.abs(run[name]).max(axis=1) >= limit * (1 - 1e-6)))
        if held > HELD:
            return "bad", f"{name} at its {limit:g} N limit on {100 * held:.3g} % of rows"
    measured = run["plant.leg_length" if scene.kind == "hexapod" else "plant.slider_position"]
    signals = {"oscillation": np.abs(np.diff(measured, 2, axis=0)).max(axis=1)}
    if scene.kind == "3t":      # a loop too soft for gravity drifts away from its reference
        signals["tracking error"] = np.abs(measured - run["controller.reference_position"]).max(axis=1)
    for what, signal in signals.items():
        quarter = len(signal) // 4
        before, last = signal[-2 * quarter:-quarter].max(), signal[-quarter:].max()
        if last > FLOOR[scene.kind] and last > GROWN * max(before, FLOOR[scene.kind] / GROWN):
            return "bad", f"{what} grows {last / max(before, 1e-300):.3g}x over the last quarter ({last:.3g} m)"
    return "clean", ""


def spec_value(text):
    return movingbase.scenarios.units.to_si(text) if isinstance(text, str) else float(text)


def kit_and_judge(scene):
    """(the kit's verdict, the judge's verdict, why): the scene run as a user would, then
    anyway (allow_unstable) if the kit refused it, for the judge."""
    values = _with_step(scene)
    try:
        result = movingbase.run(scene.file, set=values, progress=False, ci=True)   # cut short on purpose
        kit = "clean" if result.ok else "flagged"
    except spec.ScenarioError:
        kit = "refused"
        import warnings
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", movingbase.RunWarning)
            result = movingbase.run(scene.file, set=values, progress=False, ci=True, allow_unstable=True)
    verdict, why = judge(scene, result[0])
    return kit, verdict, why


def agreement(seeds):
    """{'misses': [...], 'false_alarms': [...], 'agree': n} over ``seeds``: each miss
    (seed, kind, step / predicted limit, the judge's why), each false alarm (seed, kind,
    step / predicted limit, the kit's verdict)."""
    out = {"misses": [], "false_alarms": [], "agree": 0}
    for seed in seeds:
        scene = draw(seed)
        kit, verdict, why = kit_and_judge(scene)
        if verdict == "bad" and kit == "clean":
            out["misses"].append((seed, scene.kind, scene.step / scene.limit, why))
        elif verdict == "clean" and kit != "clean":
            out["false_alarms"].append((seed, scene.kind, round(scene.step / scene.limit, 3), kit))
        else:
            out["agree"] += 1
    return out

"""Does the headline survive a real loop? The telescope scenes with real leg sensors,
computation delay, electromechanical leg actuators, the antenna's own axis servo and
wind on the subreflector, and the feedforward fed by each base-motion signal the
controller can have: (a) exact (the telescope's actual base_*), (b) commanded (its
command_base_*), (c) the axis encoders (BaseSensor source 0), (d) an IMU (source 1).

    python -m studies.realistic_loop [--ci] [--jobs N] [--dask ADDR] [--out DIR]   # run (resumable)
    python -m studies.realistic_loop --docs          # the same, then docs/realistic_loop.md
                                                     # and the charts
    python -m studies.realistic_loop --docs --part gains   # only the redesigned-gains runs, merged into
                                                           # docs/realistic_loop.json
    python -m studies.realistic_loop --from-store    # rewrite the docs and charts from
                                                     # docs/realistic_loop.json (no runs)

Every variant is scenario text made here from the shipped scenario file (the FMU tables
and connections of the effects added programmatically), written to
<out>/realistic_loop/scenarios/ so that any run can be repeated with ``python -m
scenarios FILE``. Its sweep is the feedforward; all runs go through one engine
(scenarios.runs.engine: local workers or a Dask cluster, results keyed by content, so an
interrupted study resumes). An effect that is off is not in the scenario at all: the
ideal loop is the shipped scenario, number for number.

Runs per scene: the table (feedforward none / fixed-base / moving-base with each source,
in the ideal and the realistic loop) and the error budget (the ideal loop with one effect
on at a time, for the fixed-base and the moving-base feedforward). In the slew also the
gains (controller.design on the realistic plant: the shipped method re-done and the
stiffest design within 45 deg / 6 dB on every mode) in the realistic loop, calm and
10 m/s, and a wind-speed sweep with the shipped and the stiffest gains. The paper's manoeuvre
is left out: its base motion is not an antenna's axis motion, so neither the axis servo
nor the encoder/IMU signals (built on the axis angles) apply to it.
"""
import argparse
import json
import math
import pathlib
import re
import sys
import tomllib

import matplotlib

matplotlib.use("Agg")
import matplotlib.lines
import matplotlib.patches
import matplotlib.pyplot as plt

from scenarios import spec
from scenarios.output.charts import FLOOR, FLOOR_NOTE, RUN_COLOURS, draw_marks, length, plain_log_axis, save
from scenarios.output.report import fmt
from scenarios.runs import engine, runner

ROOT = pathlib.Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
STORE = DOCS / "realistic_loop.json"
REPORT = DOCS / "realistic_loop.md"
SCENES = ("telescope_slew", "keyhole_tracking")
MODES = ("none", "fixed_base", "moving_base")
MODE_NAMES = {"none": "none", "fixed_base": "fixed-base model", "moving_base": "moving-base model"}
SOURCES = ("exact", "commanded", "encoders", "imu")
SOURCE_NAMES = {"exact": "(a) exact", "commanded": "(b) commanded", "encoders": "(c) axis encoders",
                "imu": "(d) IMU"}
EFFECTS = ("leg_sensors", "delay", "actuator", "servo", "wind")
EFFECT_NAMES = {"leg_sensors": "leg encoders (0.1 µm, noise, differenced rate)",
                "delay": "computation delay (1 sample)", "actuator": "ball-screw actuator (50 Hz, friction)",
                "servo": "antenna axis servo (0.8 Hz)", "wind": "wind (10 m/s, Kaimal gust)"}
MARKS = (10.0, 100.0)   # µm: focus, hexapod metrology
LOOPS = {"ideal": (), "calm": tuple(e for e in EFFECTS if e != "wind"), "realistic": EFFECTS}
LOOP_NAMES = {"ideal": "ideal loop", "calm": "realistic loop, calm air", "realistic": "realistic loop, 10 m/s wind"}
# The full runs' windows: every run starts at its operating point (OPERATING_POINT), so both
# scenes count from 1 s, as the shipped realistic scenes do (issue 41); the keyhole track runs
# 30 s with the transit at 16 s (the shipped 250 s run spends most of its time on the quiet
# approach and would make the study 8x longer). The [ci] runs keep the shipped files' timing and
# start (their golden metrics).
WINDOWS = {"telescope_slew": {"from": "1 s"},
           "keyhole_tracking": {"stop_time": "30 s", "utc_shift": 109.0, "from": "1 s"}}
METRIC = "pose error"
# The redesigned gains (controller.design on the realistic plant, REALISTIC): "method" is
# the shipped method re-done (8 Hz crossover, 60 deg on the heaviest mode), "stiffest" the
# largest integral gain with PM >= 45 deg and GM >= 6 dB on every mode; "shipped" is the
# controller FMU's default (designed for the ideal plant). Run in the slew only, calm and
# 10 m/s wind, and the wind-speed sweep (0 and 10 m/s are the calm and realistic loops).
GAINS = ("shipped", "method", "stiffest")
GAIN_NAMES = {"shipped": "shipped (ideal-plant design)", "method": "8 Hz / 60 deg on the realistic plant",
              "stiffest": "stiffest with PM >= 45 deg, GM >= 6 dB"}
GAIN_SCENE = "telescope_slew"
GAIN_SOURCES = ("exact", "imu")
WIND_SPEEDS = (0.0, 5.0, 10.0, 15.0)   # m/s
SWEEP_GAINS = ("shipped", "stiffest")

# The realistic loop's values. None has a public source for this telescope: each is
# assumed, from the comparable instrument named beside it; the leg and actuator values are
# those of scenarios/files/telescope_slew_realistic.toml, the servo and base-sensor values
# those of telescope_slew_base_sources.toml (which say where each comes from).
LEG_SENSOR = {"resolution": "0.1 um",   # absolute linear encoders of precision hexapods (PI H-840, Symetrie BORA)
              "noise": "0.02 um",       # RMS per sample, a fifth of the resolution
              "rate_cutoff": "100 Hz",  # low-pass of the differenced rate, a decade above the 8 Hz crossover
              "seed": 1}
DELAY = {"delay_steps": 1}              # one sample of computation on top of the communication step
ACTUATOR = {"actuator_bandwidth": "50 Hz",    # servo motor force loop closed through screw and joint compliance
            "reflected_mass": 758.0,          # kg: rotor + 25 mm screw J (2 pi / 5 mm)^2 (Siemens 1FK7 / AKM class)
            "coulomb_friction": "200 N",      # preloaded 25 mm ball nut drag torque (NSK / THK catalogues)
            "viscous_friction": "2000 N.s/m",  # lubricant and seals
            "friction_velocity": "0.1 mm/s",  # tanh smoothing of the Coulomb friction
            "actuator_force_limit": "25 kN",  # ~20 N m peak motor torque through the 5 mm pitch
            "max_step": "1 ms",               # error-controlled RK4 substeps that follow the friction's
            "tolerance": "0.0001 um"}         # steep slope, as the shipped realistic scenes (0.1 nm)
SERVO = {"servo_bandwidth": "0.8 Hz", "servo_damping": 0.7}   # large-antenna axis servos (SRT, GBT: 0.5-1 Hz)
WIND = {"mean_speed": "10 m/s", "turbulence_intensity": 0.15, "spectrum": "kaimal", "seed": 1}   # fmu_src/wind_fmu.py
BASE_SENSOR = {"encoder_resolution": "0.484813681109536 urad",   # 0.1 arcsec: GBT / Effelsberg / SRT axis encoders
               "rate_cutoff": "5 Hz",
               "gyro_noise_density": 2.908882086657216e-6,     # rad/s/sqrt(Hz) = 0.01 deg/sqrt(h): fibre-optic gyro
               "gyro_bias": 2.42406840554768e-7,               # rad/s = 0.05 deg/h
               "accel_noise_density": 4.903325e-4,             # m/s2/sqrt(Hz) = 50 ug/sqrt(Hz): navigation-grade
               "accel_bias": "0.980665 mm/s2", "seed": 1}      # 100 ug


# ------------------------------------------------------------------------ scenario text
def _toml_key(key):
    """A key as TOML takes it: bare if it can be, else quoted ("pose error peak")."""
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else json.dumps(key, ensure_ascii=False)


def _toml_value(value):
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"no TOML for {value!r}")


def toml_text(data):
    """TOML for a scenario dict (the shapes scenario files use: scalars, tables of
    scalars or inline tables, arrays of tables)."""
    lines = [f"{k} = {_toml_value(v)}" for k, v in data.items() if not isinstance(v, (dict, list))
             or (isinstance(v, list) and not (v and isinstance(v[0], dict)))]
    for key, value in data.items():
        if isinstance(value, dict) and key != "fmus":
            lines += ["", f"[{key}]"] + [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()]
        elif key == "fmus":
            for inst, table in value.items():
                lines += ["", f"[fmus.{inst}]"] + [f"{k} = {_toml_value(v)}" for k, v in table.items()]
        elif isinstance(value, list) and value and isinstance(value[0], dict):
            for item in value:
                lines += ["", f"[[{key}]]"] + [f"{k} = {_toml_value(v)}" for k, v in item.items()]
    return "\n".join(lines) + "\n"


def _reroute(data, source, target, new_source):
    """Feed ``target`` from ``new_source`` instead of ``source``."""
    for conn in data["connections"]:
        targets = [conn["to"]] if isinstance(conn["to"], str) else list(conn["to"])
        if conn["from"] == source and target in targets:
            targets.remove(target)
            if targets:
                conn["to"] = targets
            else:
                data["connections"].remove(conn)
            break
    else:
        raise ValueError(f"no connection {source} -> {target}")
    data["connections"].append({"from": new_source, "to": target})


def _connect(data, source, target):
    for conn in data["connections"]:
        if conn["from"] == source:
            conn["to"] = ([conn["to"]] if isinstance(conn["to"], str) else list(conn["to"])) + [target]
            return
    data["connections"].append({"from": source, "to": target})


# The operating point (issue 41): the plant starts holding itself still against its start
# inputs (the mean wind load included) and the controller's integral or observer starts
# holding what its feedforward lacks, as a loop that has been running long would
OPERATING_POINT = {"plant": {"start_equilibrium": 1}, "controller": {"start_force": "@plant.leg_force_actual"}}


def variant(scene, effects=(), source="exact", modes=MODES, overrides=None, window=False, gains=None,
            operating_point=False):
    """The scenario dict of ``scene`` (a shipped name) with ``effects`` (EFFECTS names) on
    and the feedforward's base motion from ``source``, swept over ``modes``.
    ``overrides``: {effect or "base_sensor": {parameter: value}} replacing the realistic
    values (the tests change one setting); ``window``: the study's time window
    (WINDOWS) instead of the shipped one; ``gains``: (tag, {"kp", "ki", "kd": value}) the
    controller's PID gains instead of its shipped ones, the tag in the scenario's name;
    ``operating_point``: the loop starts at its operating point (OPERATING_POINT)."""
    unknown = set(effects) - set(EFFECTS)
    if unknown or source not in SOURCES:
        raise ValueError(f"unknown effect {sorted(unknown)} or source {source!r}; effects: {EFFECTS}, "
                         f"sources: {SOURCES}")
    over = overrides or {}
    settings = lambda name, values: {**values, **over.get(name, {})}
    data = tomllib.loads(runner.resolve(scene).read_text())
    tag = "-".join([*sorted(effects), source]) if effects or source != "exact" else "ideal"
    data["name"] = (
        f"{scene}-{tag}"
        + (f"-gains_{gains[0]}" if gains else "")
        + (
            f"-wind_{over['wind']['mean_speed'].replace(' ', '').replace('/', '_')}"
            if "wind" in effects and "mean_speed" in over.get("wind", {})
            else ""
        )
    )
    data["description"] = (f"{data['name']}: {scene} with " + (", ".join(EFFECT_NAMES[e] for e in sorted(effects))
                           or "the ideal loop") + f"; feedforward base motion {SOURCE_NAMES[source]}.")
    data["sweep"] = {"parameter": "controller.feedforward", "values": list(modes)}
    fmus = data["fmus"]
    if gains:
        fmus["controller"].setdefault("parameters", {}).update(gains[1])
    if operating_point:
        for inst, values in OPERATING_POINT.items():
            fmus[inst].setdefault("parameters", {}).update(values)
    if window and scene in WINDOWS:
        if "stop_time" in WINDOWS[scene]:
            data["stop_time"] = WINDOWS[scene]["stop_time"]
            fmus["base"]["parameters"]["utc_start"] += WINDOWS[scene]["utc_shift"]
        for metric in data["metrics"]:
            if "from" in metric:
                metric["from"] = WINDOWS[scene]["from"]
    if "leg_sensors" in effects or "delay" in effects:
        params = {}
        if "leg_sensors" in effects:
            params.update(settings("leg_sensors", LEG_SENSOR))
        if "delay" in effects:
            params.update(settings("delay", DELAY))
        fmus["leg_sensor"] = {"fmu": "leg_sensor", "parameters": params}
        _reroute(data, "plant.leg_length", "controller.leg_length", "leg_sensor.measured_length")
        _reroute(data, "plant.leg_rate", "controller.leg_rate", "leg_sensor.estimated_rate")
        _connect(data, "plant.leg_length", "leg_sensor.leg_length")
    if "actuator" in effects:
        fmus["plant"]["parameters"].update(settings("actuator", ACTUATOR))
    if "servo" in effects:
        fmus["base"]["parameters"].update(settings("servo", SERVO))
    if "wind" in effects:
        fmus["wind"] = {"fmu": "wind", "parameters": settings("wind", WIND)}
        _connect(data, "base.base_pose", "wind.base_pose")
        data["connections"].append({"from": "wind.platform_wrench", "to": "plant.platform_wrench"})
    if source == "commanded":
        for part in ("pose", "rate", "acc"):
            _reroute(data, f"base.base_{part}", f"controller.base_{part}", f"base.command_base_{part}")
    elif source in ("encoders", "imu"):
        lever_arm = fmus["base"]["parameters"].get("lever_arm", "25 m")
        fmus["base_sensor"] = {"fmu": "base_sensor", "parameters": {
            "source": source, "lever_arm": lever_arm, **settings("base_sensor", BASE_SENSOR)}}
        for part in ("pose", "rate", "acc"):
            _reroute(data, f"base.base_{part}", f"controller.base_{part}", f"base_sensor.base_{part}")
            _connect(data, f"base.base_{part}", f"base_sensor.true_base_{part}")
        _connect(data, "base.axis", "base_sensor.axis")
        _connect(data, "base.axis_rate", "base_sensor.axis_rate")
    return data


def cases(scenes=SCENES):
    """(scene, loop, source, effects, modes) of every variant the study runs: the table
    (ideal and realistic loop, each source) and the budget (one effect at a time)."""
    out = []
    for scene in scenes:
        for loop, effects in LOOPS.items():
            out.append((scene, loop, "exact", effects, MODES))
            for source in SOURCES[1:]:   # none and fixed-base ignore the base motion: once is enough
                out.append((scene, loop, source, effects, ("moving_base",)))
        for effect in EFFECTS:
            out.append((scene, effect, "exact", (effect,), ("fixed_base", "moving_base")))
    return out


def designs():
    """{name: Design} of the redesigned gains on the realistic plant, and the shipped
    gains' margins on it (controller.design; ~20 s for the search)."""
    from controller import design
    from plant.hexapod.model import StewartParams
    params = StewartParams.paper()
    shipped = design.default_gains(params)
    return {"shipped": design.margins(params, shipped, 1e-3, design.REALISTIC),
            "method": design.design_pid(params, design.DEFAULT_CROSSOVER_HZ, design.DEFAULT_PHASE_MARGIN_DEG, 1e-3,
                                        loop=design.REALISTIC),
            "stiffest": design.stiffest_pid(params, 1e-3)}


def design_summary(found):
    """What the docs say of each design: gains, heavy-mode crossover and margins, the worst
    margins over the modes (dB, deg, N/m, N/(m s), N s/m)."""
    return {name: {"kp": d.gains.kp, "ki": d.gains.ki, "kd": d.gains.kd, "crossover_hz": d.crossover_hz,
                   "phase_margin_deg": d.phase_margin_deg, "modal_phase_margin_deg": d.modal_phase_margin_deg,
                   "modal_gain_margin_db": d.modal_gain_margin_db,
                   "modal_lower_gain_margin_db": d.modal_lower_gain_margin_db}
            for name, d in found.items()}


def _wind_key(speed, gains):
    """The results' loop key of the slew at wind ``speed`` with ``gains``: 0 and 10 m/s with
    the shipped gains are the calm and realistic loops of the table."""
    base = {0.0: "calm", 10.0: "realistic"}.get(speed, f"wind {speed:g} m/s")
    return base if gains == "shipped" else f"{base} | {gains}"


def gain_cases(summaries):
    """The redesigned-gains cases: (scene, loop key, source, effects, modes, overrides,
    (tag, gains)) for each design in ``summaries`` (design_summary) but the shipped one,
    calm and 10 m/s, and the wind sweep's other speeds for SWEEP_GAINS."""
    out = []
    pid = lambda name: (name, {k: summaries[name][k] for k in ("kp", "ki", "kd")}) if name != "shipped" else None
    for name in GAINS[1:]:
        for loop in ("calm", "realistic"):
            out.append((GAIN_SCENE, f"{loop} | {name}", "exact", LOOPS[loop], MODES, None, pid(name)))
            out += [(GAIN_SCENE, f"{loop} | {name}", src, LOOPS[loop], ("moving_base",), None, pid(name))
                    for src in GAIN_SOURCES[1:]]
    for name in SWEEP_GAINS:
        for speed in WIND_SPEEDS:
            if speed in (0.0, 10.0):
                continue
            wind = {"wind": {"mean_speed": f"{speed:g} m/s"}}
            out.append((GAIN_SCENE, _wind_key(speed, name), "exact", EFFECTS, ("fixed_base",), wind, pid(name)))
            out.append((GAIN_SCENE, _wind_key(speed, name), "imu", EFFECTS, ("moving_base",), wind, pid(name)))
    return out


# ------------------------------------------------------------------------ running
def run(out="out", ci=False, jobs=None, address=None, progress=True, scenes=SCENES, selected=None):
    """Run every variant (or the ``selected`` cases) not on disk yet; returns the results
    {scene: {loop: {source: {mode: record}}}} (record: the engine's run record) and the
    scenario paths."""
    folder = pathlib.Path(out) / "realistic_loop" / ("ci" if ci else "full")
    texts = folder / "scenarios"
    texts.mkdir(parents=True, exist_ok=True)
    store = engine.Store(folder / "runs")
    everything, files, index = [], {}, []
    for scene, loop, source, effects, modes, *more in (selected or cases(scenes)):
        overrides, gains = (list(more) + [None, None])[:2]
        data = variant(scene, effects, source, modes, overrides, window=not ci, gains=gains, operating_point=not ci)
        path = texts / f"{data['name']}.toml"
        path.write_text(toml_text(data))
        scenario, paths, descriptions, values = runner.prepare(path, ci)
        items = [spec.sweep_value(scenario, descriptions, mode) for mode in modes]
        jobs_here, files_here = engine.prepared_jobs(scenario, paths, values,
                                                     [(m, {i: {n: v}}) for m, (i, n, v) in zip(modes, items)],
                                                     keep_record=False)
        everything += jobs_here
        files.update(files_here)
        index += [(scene, loop, source, job.label, job) for job in jobs_here]
    with engine.Engine(jobs, address) as eng:
        outcome = eng.run(everything, files, store, progress, name="realistic_loop")
    if outcome.interrupted:
        raise KeyboardInterrupt
    results = {}
    for scene, loop, source, mode, job in index:
        record = store.read(job.key) if store.status(job.key) else {"status": "not run"}
        results.setdefault(scene, {}).setdefault(loop, {}).setdefault(source, {})[mode] = record
    return results


def summary(results):
    """The numbers the docs use: {scene: {loop: {source: {mode: {rms, peak, rotation_rms,
    rotation_peak, us_per_step}}}}} in µm / µrad, None for a failed run."""
    out = {}
    for scene, loops in results.items():
        for loop, sources in loops.items():
            for source, modes in sources.items():
                for mode, record in modes.items():
                    entry = None
                    if record.get("status") == "ok":
                        m = record["metrics"][METRIC]
                        entry = {k: m[k] for k in ("rms", "peak", "rotation_rms", "rotation_peak")}
                        entry["us_per_step"] = 1e6 * record["run_time_s"] / record["steps"]
                    out.setdefault(scene, {}).setdefault(loop, {}).setdefault(source, {})[mode] = entry
    return out


# ------------------------------------------------------------------------ what the docs say
def _scenes(s):
    """The scenes in the stored results (the store also holds the designs)."""
    return [scene for scene in s if scene in SCENES]


def _get(s, scene, loop, source, mode):
    entry = s.get(scene, {}).get(loop, {}).get(source, {}).get(mode)
    if entry is None and mode != "moving_base":   # none / fixed-base ran once, with the exact source
        entry = s.get(scene, {}).get(loop, {}).get("exact", {}).get(mode)
    return entry


def _pair(entry, key):
    return "failed" if entry is None else f"{fmt(entry[key])}"


def _mark(value):
    """Where a peak lies against the two marks."""
    if value is None:
        return "failed"
    return "under 10 µm" if value < MARKS[0] else "under 0.1 mm" if value < MARKS[1] else "past 0.1 mm"


def table(s):
    """The headline table extended: one row per scene, feedforward and source."""
    lines = ["| scene | feedforward | base motion | " + " | ".join(f"{LOOP_NAMES[l]}: RMS / peak [µm]" for l in LOOPS)
             + " | realistic peaks against the marks (calm / wind) |", "|---|---|---|" + "---|" * (len(LOOPS) + 1)]
    for scene in _scenes(s):
        first = True
        for mode in MODES:
            for source in (SOURCES if mode == "moving_base" else ("exact",)):
                entries = [_get(s, scene, loop, source, mode) for loop in LOOPS]
                label = SOURCE_NAMES[source] if mode == "moving_base" else "not used"
                cells = [f"{_pair(e, 'rms')} / {_pair(e, 'peak')}" for e in entries]
                marks = " / ".join(_mark(e["peak"] if e else None) for e in entries[1:])
                lines.append(f"| {f'`{scene}`' if first else ''} | {MODE_NAMES[mode]} | {label} | "
                             f"{' | '.join(cells)} | {marks} |")
                first = False
    return "\n".join(lines)


def _ratio(a, b):
    return a / b if b else math.inf


def _pp(entry):
    return f"{fmt(entry['peak'])} / {fmt(entry['rms'])} µm"


def _verdict(ratios):
    """What fixed-base / moving-base peak ratios ({signal: ratio}) say."""
    best = max(ratios, key=ratios.get)
    if ratios[best] > 1.5:
        return (
            f"the moving-base model still beats the fixed-base one, best by {fmt(ratios[best])}x ({SOURCE_NAMES[best]})"
        )
    if min(ratios.values()) >= 1 / 1.5:
        return "the two models are within 1.5x of each other: the base-motion model no longer matters"
    return "the fixed-base model does better"


def statements(s):
    """One plain paragraph per scene: does the moving-base model still beat the fixed-base
    one in the realistic loop (calm air and wind), by how much, and with which base-motion
    signal it is enough (enough: its peak under the 10 µm mark and within 2x of the exact
    signal's). Errors as peak / RMS pose error."""
    out = []
    for scene in _scenes(s):
        ideal_f, ideal_m = _get(s, scene, "ideal", "exact", "fixed_base"), _get(s, scene, "ideal", "exact",
                                                                                "moving_base")
        parts = [f"- **`{scene}`** (peak / RMS pose error). Ideal loop: fixed-base {_pp(ideal_f)}, moving-base "
                 f"{_pp(ideal_m)} ({fmt(_ratio(ideal_f['peak'], ideal_m['peak']))}x in peak)."]
        for loop in ("calm", "realistic"):
            fixed = _get(s, scene, loop, "exact", "fixed_base")
            moving = {src: _get(s, scene, loop, src, "moving_base") for src in SOURCES}
            if fixed is None or any(v is None for v in moving.values()):
                parts.append(f"{LOOP_NAMES[loop].capitalize()}: some runs failed (docs/realistic_loop.md).")
                continue
            ratios = {src: _ratio(fixed["peak"], m["peak"]) for src, m in moving.items()}
            enough = [SOURCE_NAMES[src] for src, m in moving.items()
                      if m["peak"] < MARKS[0] and m["peak"] <= 2 * moving["exact"]["peak"]]
            parts.append(
                f"{LOOP_NAMES[loop].capitalize()}: fixed-base {_pp(fixed)} ({_mark(fixed['peak'])}), moving-base "
                + ", ".join(f"{SOURCE_NAMES[src]} {_pp(m)}" for src, m in moving.items())
                + "; fixed-base / moving-base peak " + ", ".join(f"{fmt(r)}x {SOURCE_NAMES[src][:3]}"
                                                                for src, r in ratios.items())
                + f": {_verdict(ratios)}. Signals that are enough (peak under 10 µm, within 2x of the exact "
                f"motion's): {', '.join(enough) if enough else 'none'}.")
        wind = {m: _get(s, scene, "wind", "exact", m) for m in ("fixed_base", "moving_base")}
        if all(wind.values()):
            parts.append(f"The wind alone: fixed-base {_pp(wind['fixed_base'])}, moving-base "
                         f"{_pp(wind['moving_base'])}.")
        out.append(" ".join(parts))
    return "\n".join(out)


def budget_rows(s, scene):
    """[(label, {mode: entry})] of the budget chart: the ideal loop, each effect alone,
    each base-motion signal alone (moving-base only), everything."""
    rows = [("ideal loop", {m: _get(s, scene, "ideal", "exact", m) for m in ("fixed_base", "moving_base")})]
    for effect in EFFECTS:
        rows.append((f"+ {EFFECT_NAMES[effect]}", {m: _get(s, scene, effect, "exact", m)
                                                   for m in ("fixed_base", "moving_base")}))
    for source in SOURCES[2:]:
        rows.append((f"+ base motion from {SOURCE_NAMES[source][4:]}",
                     {"moving_base": _get(s, scene, "ideal", source, "moving_base")}))
    for loop, what in (("calm", "all but wind"), ("realistic", "all effects")):
        rows.append((f"{what}, base motion exact", {m: _get(s, scene, loop, "exact", m)
                                                    for m in ("fixed_base", "moving_base")}))
        for source in SOURCES[1:]:
            rows.append((f"{what}, base motion {SOURCE_NAMES[source][4:]}",
                         {"moving_base": _get(s, scene, loop, source, "moving_base")}))
    return rows


def budget_chart(s, scene, path):
    """Horizontal bars, peak and RMS pose error per row on one shared log axis floored at
    1 nm, each model in its colour, the two marks drawn, the values in a column at the
    right of each panel (clear of the marks); rows that vary only the moving-base model's
    base-motion signal say so in the fixed-base slot. Returns the two axes (the figure is
    closed)."""
    rows = budget_rows(s, scene)
    fig, axes = plt.subplots(1, 2, figsize=(13, 0.44 * len(rows) + 1.8), sharey=True, layout="constrained")
    values = [e[k] for _, row in rows for e in row.values() if e for k in ("rms", "peak")]
    low, high = FLOOR, max(max(values) * 3, 300.0)
    for ax, key, title in zip(axes, ("peak", "rms"), ("peak pose error", "RMS pose error")):
        for i, (label, row) in enumerate(rows):
            for j, mode in enumerate(("fixed_base", "moving_base")):
                y = i + (j - 0.5) * 0.38
                if mode not in row:
                    ax.text(low * 1.5, y, "moving-base model only (a base-motion signal)",
                            va="center", fontsize=7.5, color="0.45", style="italic")
                    continue
                entry = row[mode]
                if entry is None:
                    text, colour = "failed", "red"
                else:
                    text, colour = length(entry[key]), RUN_COLOURS[mode]
                    if entry[key] < low:   # under the floor: a triangle on it
                        ax.plot(low, y, marker="<", color=colour, ms=7, clip_on=False)
                    else:
                        ax.barh(y, entry[key] - low, left=low, height=0.36, color=colour)
                ax.text(1.01, y, text, transform=ax.get_yaxis_transform(), va="center", fontsize=7.5, color=colour)
        draw_marks(ax, vertical=True)
        for mode, entry in rows[0][1].items():   # the ideal loop's value, down the chart, in the model's colour
            if entry:
                ax.axvline(max(entry[key], low), color=RUN_COLOURS[mode], lw=1.2, ls=(0, (1, 2)), zorder=0)
        for edge in (0.5, len(EFFECTS) + len(SOURCES[2:]) + 0.5, len(EFFECTS) + len(SOURCES[2:]) + len(SOURCES) + 0.5):
            ax.axhline(edge, color="black", lw=0.6)
        ax.set_xscale("log")
        plain_log_axis(ax.xaxis, subs=(1.0,))
        ax.set_xlim(low, high)
        ax.set_xlabel(f"{title} [µm], from 1 s (log scale)")
        ax.grid(axis="x", which="major", alpha=0.3)
        ax.set_title(title, pad=14)
    axes[0].set_yticks(range(len(rows)), [label for label, _ in rows], fontsize=8.5)
    axes[0].set_ylim(len(rows) - 0.5, -0.6)
    handles = [matplotlib.patches.Patch(color=RUN_COLOURS[m], label=MODE_NAMES[m]) for m in ("fixed_base",
                                                                                             "moving_base")]
    handles.append(matplotlib.lines.Line2D([], [], color="0.3", lw=1.2, ls=(0, (1, 2)),
                                           label="the ideal loop's value (each model in its colour)"))
    fig.legend(handles=handles, loc="outside lower center", ncol=3, fontsize=8.5, frameon=False)
    fig.suptitle(f"{scene}: pose error with each effect alone on top of the ideal loop, and with everything on\n"
                 f"{FLOOR_NOTE}; values under it written '< 1 nm'", fontsize=10)
    save(fig, path)
    return axes


def _gain_entry(s, gains, loop, source, mode):
    key = loop if gains == "shipped" else f"{loop} | {gains}"
    return _get(s, GAIN_SCENE, key, source, mode)


def design_table(s):
    """The designs on the realistic plant (controller.design.REALISTIC): gains, the heaviest
    mode's crossover and phase margin, the worst margins over the six modes."""
    lines = ["| gains | kp [N/m] | ki [N/(m s)] | kd [N s/m] | heaviest mode: crossover [Hz] / PM [deg] | "
             "worst mode: PM [deg] / GM up, down [dB] |", "|---|---|---|---|---|---|"]
    for name, d in s["designs"].items():
        lines.append(f"| {GAIN_NAMES[name]} | {d['kp']:.3g} | {d['ki']:.3g} | {d['kd']:.3g} | "
                     f"{d['crossover_hz']:.2f} / {d['phase_margin_deg']:.1f} | {d['modal_phase_margin_deg']:.1f} / "
                     f"{d['modal_gain_margin_db']:.1f}, {-d['modal_lower_gain_margin_db']:.1f} |")
    return "\n".join(lines)


def gains_table(s):
    """Peak / RMS pose error of the slew per gains and feedforward, calm and 10 m/s."""
    lines = ["| gains | feedforward | base motion | " + " | ".join(f"{LOOP_NAMES[l]}: RMS / peak [µm]"
                                                             for l in ("calm", "realistic")) + " |",
             "|---|---|---|---|---|"]
    for name in GAINS:
        for mode, source in (("none", "exact"), ("fixed_base", "exact"), ("moving_base", "exact"),
                             ("moving_base", "imu")):
            cells = [_gain_entry(s, name, loop, source, mode) for loop in ("calm", "realistic")]
            label = SOURCE_NAMES[source] if mode == "moving_base" else "not used"
            lines.append(f"| {GAIN_NAMES[name]} | {MODE_NAMES[mode]} | {label} | "
                         + " | ".join(f"{_pair(e, 'rms')} / {_pair(e, 'peak')}" for e in cells) + " |")
    return "\n".join(lines)


def sweep_lines(s):
    """{(gains, mode): [peak or None per WIND_SPEEDS]} of the wind sweep: fixed-base, and
    moving-base fed by the IMU."""
    out = {}
    for name in SWEEP_GAINS:
        for mode, source in (("fixed_base", "exact"), ("moving_base", "imu")):
            entries = [_get(s, GAIN_SCENE, _wind_key(u, name), source, mode) for u in WIND_SPEEDS]
            out[name, mode] = [e["peak"] if e else None for e in entries]
    return out


def sweep_chart(s, path):
    """Peak pose error of the slew against mean wind speed, one line per gains x
    feedforward (colour: the model; line, marker and fill: the gains), the 10 µm mark
    drawn; log y labelled at 1, 2, 5 per decade (the calm peaks sit far below the windy
    ones). Returns the axes (the figure is closed)."""
    fig, ax = plt.subplots(figsize=(9, 5.8), layout="constrained")
    styles = {"shipped": {"ls": "-", "marker": "o", "ms": 7},
              "stiffest": {"ls": (0, (6, 3)), "marker": "s", "ms": 6, "mfc": "white", "mew": 1.5}}
    for (name, mode), peaks in sweep_lines(s).items():
        points = [(u, p) for u, p in zip(WIND_SPEEDS, peaks) if p is not None]
        ax.plot(*zip(*points), color=RUN_COLOURS[mode], lw=1.6, **styles[name],
                label=f"{GAIN_NAMES[name]}, {MODE_NAMES[mode]}" + (" (IMU)" if mode == "moving_base" else ""))
    draw_marks(ax, top=max(p for peaks in sweep_lines(s).values() for p in peaks if p is not None))
    ax.set_yscale("log")
    plain_log_axis(ax.yaxis)
    ax.set_xticks(WIND_SPEEDS)
    ax.set_xlabel("mean wind speed [m/s] (Kaimal gusts, 15 % turbulence)")
    ax.set_ylabel("peak pose error from 1 s [µm] (log)")
    ax.set_title(f"{GAIN_SCENE}, realistic loop: peak pose error against wind speed", fontsize=10)
    ax.grid(which="major", alpha=0.3)
    fig.legend(*ax.get_legend_handles_labels(), fontsize=8, loc="outside lower center", ncol=2, frameon=False,
               handlelength=4)
    save(fig, path)
    return ax


def gain_statements(s):
    """One paragraph: what the designs are on the realistic plant, and what the redesigned
    gains do in calm air and wind to the fixed-base and the moving-base (IMU) feedforward."""
    d = s["designs"]
    ship, method, stiff = d["shipped"], d["method"], d["stiffest"]
    parts = [
        f"- **Gains for the realistic plant** (`{GAIN_SCENE}`; controller.design with the 758 kg reflected "
        f"mass, the 50 Hz force loop, the encoders' rate filter and delays and the master's extrapolation). The "
        f"shipped gains (designed for the ideal plant) keep {ship['modal_phase_margin_deg']:.0f} deg and "
        f"{ship['modal_gain_margin_db']:.1f} dB on the worst mode of the realistic plant, the heaviest mode "
        f"crossing at {ship['crossover_hz']:.1f} Hz. The shipped method re-done (8 Hz, 60 deg on the heaviest "
        f"mode) is reachable but leaves the lightest mode {method['modal_phase_margin_deg']:.0f} deg and "
        f"{method['modal_gain_margin_db']:.1f} dB. The stiffest design with PM >= 45 deg and GM >= 6 dB on every "
        f"mode crosses at {stiff['crossover_hz']:.2f} Hz with ki {fmt(stiff['ki'] / ship['ki'])}x and kp "
        f"{fmt(stiff['kp'] / ship['kp'])}x the shipped gains': within those margins the loop "
        f"{'cannot be ' if stiff['ki'] < ship['ki'] else 'is '}"
        + ("as stiff as the shipped one, which trades margin for stiffness" if stiff["ki"] < ship["ki"]
           else "stiffer than the shipped one") + "."
    ]
    for loop in ("calm", "realistic"):
        peaks = {name: {ff: _gain_entry(s, name, loop, src, mode) for ff, (mode, src) in
                        (("fixed", ("fixed_base", "exact")), ("imu", ("moving_base", "imu")))} for name in GAINS}
        if any(e is None for row in peaks.values() for e in row.values()):
            parts.append(f"{LOOP_NAMES[loop].capitalize()}: some runs failed.")
            continue
        parts.append(f"{LOOP_NAMES[loop].capitalize()}, peak pose error fixed-base / moving-base (IMU): " + "; ".join(
            f"{GAIN_NAMES[name]} {fmt(row['fixed']['peak'])} / {fmt(row['imu']['peak'])} µm "
            f"({fmt(_ratio(row['fixed']['peak'], row['imu']['peak']))}x)" for name, row in peaks.items()) + ".")
    lines = sweep_lines(s)
    if all(p is not None for peaks in lines.values() for p in peaks):
        ratios = {name: [_ratio(f, m) for f, m in zip(lines[name, "fixed_base"], lines[name, "moving_base"])]
                  for name in SWEEP_GAINS}
        stiffer = {mode: [_ratio(b, a) for a, b in zip(lines["shipped", mode], lines["stiffest", mode])]
                   for mode in ("fixed_base", "moving_base")}
        windy = [i for i, u in enumerate(WIND_SPEEDS) if u > 0]
        parts.append(
            f"Wind sweep ({', '.join(f'{u:g}' for u in WIND_SPEEDS)} m/s, docs/figures/realistic_wind_sweep.png), peak "
            f"of the stiffest design over the shipped gains' per speed: fixed-base "
            + ", ".join(fmt(r) for r in stiffer["fixed_base"])
            + ", moving-base (IMU) "
            + ", ".join(fmt(r) for r in stiffer["moving_base"])
            + "; fixed-base / moving-base (IMU) peak per speed, shipped "
            + ", ".join(fmt(r) for r in ratios["shipped"])
            + ", stiffest "
            + ", ".join(fmt(r) for r in ratios["stiffest"])
            + ". "
            + (
                f"So the shipped loop's extra stiffness (ki {fmt(ship['ki'] / stiff['ki'])}x) buys "
                f"{fmt(min(stiffer['fixed_base'][i] for i in windy))}-"
                f"{fmt(max(stiffer['fixed_base'][i] for i in windy))}x "
                f"lower fixed-base peaks in wind, paid for with {ship['modal_phase_margin_deg']:.0f} deg "
                "of phase margin"
                if min(stiffer["fixed_base"][i] for i in windy) > 1
                else "The extra stiffness of the shipped loop does not lower every windy peak"
            )
            + "; the moving-base model keeps a lead of 1.5x or more over the fixed-base one in wind at "
            + (
                ", ".join(
                    f"{WIND_SPEEDS[i]:g} m/s with the {name} gains"
                    for name in SWEEP_GAINS
                    for i in windy
                    if ratios[name][i] >= 1.5
                )
                or "no speed"
            )
            + "."
        )
    return " ".join(parts)


def costs(s):
    """Mean wall time per macro step of the ideal and the realistic loop (exact source),
    over the scenes, µs."""
    out = {}
    for loop in ("ideal", "realistic"):
        times = [e["us_per_step"] for scene in _scenes(s) for e in (s[scene].get(loop, {}).get("exact",
                                                                                               {}) or {}).values()
                 if e]
        out[loop] = sum(times) / len(times) if times else float("nan")
    return out


def settings_text():
    rows = [("leg sensors (LegSensor)", LEG_SENSOR), ("computation delay (LegSensor)", DELAY),
            ("actuator (HexapodPlant)", ACTUATOR), ("antenna axis servo (Telescope)", SERVO),
            ("wind (Wind)", WIND),
            ("base sensors (BaseSensor), in SI: 0.1 arcsec encoders, gyro 0.01 deg/√h and 0.05 deg/h, accelerometer "
             "50 µg/√Hz and 100 µg", BASE_SENSOR)]
    return "\n".join(f"| {name} | {', '.join(f'`{k} = {v}`' for k, v in values.items())} |" for name, values in rows)


def report(s, charts=True):
    """docs/realistic_loop.md (and the budget charts)."""
    lines = ["# Does the headline survive a real loop?", "",
             "Generated by `python -m studies.realistic_loop --docs` from `docs/realistic_loop.json`. "
             "Pose position error from 1 s in both scenes (every run starts at its operating point, as the "
             "shipped realistic and wind scenes do, [wind-rejection.md](wind-rejection.md): the plant holding "
             "itself still against its start inputs, the mean wind load included, and the controller's "
             "integral or observer holding what its feedforward lacks) against the 10 µm "
             "(focus) and 0.1 mm (hexapod metrology) marks. The slew is the shipped 60 s run; the keyhole track "
             "is 30 s with the transit at 16 s (the shipped run is 250 s, most of it the quiet approach). The ideal "
             "loop is the headline's: exact leg lengths and rates, the force in the leg at once, the antenna on its "
             "command, no wind. The realistic loop switches every effect on, in calm air or in a 10 m/s wind; the "
             "scenario file of every run is written to `out/realistic_loop/full/scenarios/` (`movingbase run "
             "FILE` repeats it). Settings:", "", "| effect | settings (assumed; see the docs' assumptions) |",
             "|---|---|",
             settings_text(), "", "## The headline table, extended", "", table(s), "", "## What survives", "",
             statements(s), "", "## Error budget: each effect alone", ""]
    for scene in _scenes(s):
        name = f"realistic_budget_{scene}.png"
        if charts:
            budget_chart(s, scene, DOCS / "figures" / name)
        lines += [f"![{scene} error budget](figures/{name})", ""]
    if "designs" in s:
        name = "realistic_wind_sweep.png"
        if charts:
            sweep_chart(s, DOCS / "figures" / name)
        lines += ["## Gains for the realistic plant", "",
                  "`controller.design` with the realistic loop's model (`REALISTIC`: per leg-space mode the mass plus "
                  "758 kg, the 50 Hz force lag, 2000 N s/m viscous friction; the encoders' 100 Hz filtered difference, "
                  "their one step of latency and one sample of computation delay; the controller's step; the Jacobi "
                  "master's linear extrapolation on the three connections; Coulomb friction, quantisation and noise "
                  "left out). Margins on that plant:", "", design_table(s), "",
                  f"The `{GAIN_SCENE}` in the realistic loop with each set of gains:", "", gains_table(s), "",
                  gain_statements(s), "", f"![wind sweep](figures/{name})", ""]
    c = costs(s)
    lines += ["## Cost", "", f"Wall time per 1 ms macro step, mean over the scenes' runs with the exact base motion "
              f"(the machine shared with other work): ideal loop (three FMUs) {c['ideal']:.0f} µs, realistic loop "
              "(five: + LegSensor, Wind; the plant's error-controlled substeps for the friction, tolerance 0.1 nm) "
              f"{c['realistic']:.0f} µs ({c['realistic'] / c['ideal']:.2f}x). An effect that is off is not in the "
              "scenario, so it costs nothing.", ""]
    REPORT.write_text("\n".join(lines))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ci", action="store_true", help="the short [ci] runs (not for the docs)")
    parser.add_argument("--jobs", type=int, help="worker processes (default: all cores)")
    parser.add_argument("--dask", metavar="ADDR", help="an existing Dask scheduler")
    parser.add_argument("--out", default="out")
    parser.add_argument("--docs", action="store_true", help="write docs/realistic_loop.* and the charts")
    parser.add_argument("--part", choices=("all", "gains"), default="all",
                        help="gains: only the redesigned-gains cases, merged into docs/realistic_loop.json with --docs")
    parser.add_argument("--from-store", action="store_true",
                        help="only rewrite the docs and charts from docs/realistic_loop.json")
    args = parser.parse_args(argv)
    if args.from_store:
        stored = json.loads(STORE.read_text())
        report(stored)
        return
    if args.docs and args.ci:
        sys.exit("--docs takes the full runs, not --ci")
    found = design_summary(designs())
    selected = gain_cases(found) if args.part == "gains" else cases() + gain_cases(found)
    s = summary(run(args.out, args.ci, args.jobs, args.dask, selected=selected))
    if args.part == "gains":   # on top of the stored table and budget runs
        stored = json.loads(STORE.read_text())
        for loop, sources in s[GAIN_SCENE].items():
            stored[GAIN_SCENE][loop] = sources
        s = stored
    s["designs"] = found
    print(table(s))
    print(statements(s))
    print(gain_statements(s))
    if args.docs:
        STORE.write_text(json.dumps(s, indent=1) + "\n")
        report(s)
        print(f"wrote {REPORT.relative_to(ROOT)} and the budget charts")


if __name__ == "__main__":
    main()

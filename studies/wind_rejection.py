"""Wind rejection: what brings the subreflector under 10 µm in gusty wind (issue 29)?

The realistic loop of studies/realistic_loop.py (every effect on, the moving-base
feedforward on the exact base motion) with each rejection scheme of SCHEMES, on
``telescope_slew`` (the shipped 60 s) and ``keyhole_tracking`` (30 s, transit at 16 s, as
realistic_loop.py cuts it) at 0, 5, 10 and 15 m/s mean wind (Kaimal gusts, 15 %
turbulence; 0: no wind FMU, the realistic loop's calm air). Plus the bound: the peak at
10 m/s against the observer's bandwidth, and the guard's predicted limit of it.

    python -m studies.wind_rejection [--jobs N] [--dask ADDR] [--out DIR]   # run (resumable)
    python -m studies.wind_rejection --docs         # the same, then docs/wind-rejection.md + charts
    python -m studies.wind_rejection --from-store   # rewrite the docs from docs/wind_rejection.json

A scheme is a table of scenario changes (FMUs added, parameters set, connections made)
applied to realistic_loop.variant's scenario, so another scheme (the anemometer's wind
feedforward) is one more row. Every scenario file is written to
<out>/wind_rejection/scenarios/ (``movingbase run FILE`` repeats it).
"""
import argparse
import copy
import json
import pathlib
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from scenarios import spec
from scenarios.output.charts import draw_marks, plain_log_axis, save
from scenarios.output.report import fmt
from scenarios.runs import engine, runner
from scenarios.runs.metrics import loss_key
from studies import realistic_loop as rl

ROOT = pathlib.Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
STORE = DOCS / "wind_rejection.json"
REPORT = DOCS / "wind-rejection.md"
SCENES = rl.SCENES
SPEEDS = (0.0, 5.0, 10.0, 15.0)   # m/s
GOAL = 10.0                        # µm, peak pose position error
TODAY = {"telescope_slew": {0.0: 5.53, 10.0: 41.9}, "keyhole_tracking": {10.0: 76.0}}   # docs/realistic_loop.md
# The observer's mass per mode (issue 41, goal 2): observer_model leg_space, the controller's model
# M_leg at home shifted to the mean diagonal OBSERVER_MASS; 1847.67 kg (M_leg's mean diagonal) + the
# plant's 758 kg reflected is the plant's own matrix, so every mode meets its own mass (1352-4178 kg)
# instead of one scalar (2000 kg before, which set the lightest modes' margins)
OBSERVER_MODEL = "leg_space"
OBSERVER_MASS = 2605.67
# Before it (issue 41's first tuning): one scalar 2000 kg at 20 Hz, kept as a row of the seed table
SCALAR = {"observer_model": "scalar", "observer_mass": 2000.0}
SCALAR_BANDWIDTH = 20.0
# The legs' load cells (LoadCell): none of these is public for this hexapod; ASSUMED from
# strain-gauge cells of a 25 kN range (the actuator's force limit): 0.02 % of range RMS
# noise, a 24-bit converter's step far below it (0.5 N), 200 Hz amplifier low-pass
# (anti-aliasing below the 500 Hz Nyquist of the 1 ms step), no extra delay.
LOAD_CELL = {"resolution": "0.5 N", "noise": "5 N", "bandwidth": "200 Hz", "delay_steps": 0, "seed": 2}
# Hz: controller.design.design_observer at DESIGN_MARGINS (bandwidth()): 32.2 Hz (the scalar 2000 kg
# kept 12 deg / 2.5 dB only to 20.6 Hz). Issue 29's 8 Hz (25 deg, 5 dB at a scalar 2606 kg) held
# 10 µm on its one gust seed only; the scalar's 20 Hz reached 10.4 µm on unseen seeds at turbulence 0.3.
# On the tuning seeds 2-9 at 0.3 (keyhole track, 10 m/s) the leg-space observer's worst peak was
# 7.57 µm at 25.8 Hz (23 deg / 4 dB), 7.19 at 28 Hz, 6.64 at 32 Hz
OBSERVER_BANDWIDTH = 32.0
DESIGN_MARGINS = (20.0, 3.0)   # deg, dB on every leg-space mode
# kg: the reflected mass misjudged by this much (the margins' robustness, bandwidth())
MASS_ERRORS = (-300.0, 300.0)
SCHEMES: dict[str, dict] = {
    "pid": {"name": "PID + moving-base feedforward (today)"},
    "observer": {
        "name": f"+ disturbance observer on load cells ({OBSERVER_BANDWIDTH:g} Hz)",
        "fmus": {"load_cell": {"fmu": "load_cell", "parameters": LOAD_CELL}},
        "parameters": {"controller": {"observer_bandwidth": f"{OBSERVER_BANDWIDTH:g} Hz",
                                      "observer_model": OBSERVER_MODEL, "observer_mass": OBSERVER_MASS}},
        "connections": [{"from": "plant.leg_force_actual", "to": "load_cell.leg_force"},
                        {"from": "load_cell.measured_force", "to": "controller.leg_force_measured"}]},
}
# The anemometer's wind feedforward as scenarios/files/telescope_slew_wind_feedforward.toml ships
# it (studies/wind_feedforward.py has its variants): the rim, a cup's 0.25 s lag, 0.1 Hz low-pass
SCHEMES["anemometer"] = {
    "name": "+ wind feedforward from a rim anemometer",
    "parameters": {"controller": {"wind_feedforward": 1.0, "wind_cutoff": "0.1 Hz"},
                   "wind": {"anemometer_distance": "3.25 m", "anemometer_time_constant": "0.25 s"}},
    "connections": [{"from": "wind.anemometer_speed", "to": "controller.wind_speed"}]}
BOUND_BANDWIDTHS = (2.0, 4.0, 8.0, 12.0, 16.0, 20.0, 24.0, 32.0, 40.0)   # Hz, at 10 m/s
BOUND_SPEED = 10.0
# Counted from 1 s in every run: the loop starts at its operating point (studies/realistic_loop.py
# OPERATING_POINT), so there is no start to wait out; the shipped scenes count from the same 1 s
FROM = "1 s"
# The gusts the shipped configuration was not tuned on: issue 29 tuned it on seed 1, issue 41
# chose its bandwidth on seeds 2-9 at intensity 0.3 (TUNING_SEEDS); the table runs 16 others at two
# turbulence intensities (0.15: open site; 0.3: gusty sites, the quadripod's wake), at 10 m/s
# and at 15 m/s, the observer on
TUNING_SEEDS = tuple(range(1, 10))
GUST_SEEDS = tuple(range(10, 26))
# and the gustiest case (keyhole track, 10 m/s, intensity 0.3) on 15 more, for its tail
MORE_SEEDS = tuple(range(26, 41))
INTENSITIES = (0.15, 0.3)
GUST_SPEEDS = (10.0, 15.0)
# A load that arrives as a step: the slew's loop at its calm-air operating point (the plant's
# leg_force start is the static load at the start pointing, fmu_src/operating_point.py; the
# controller's integral and observer at rest) meets the whole mean wind at t = 0, a gust
# front; counted from 0 s over the 5 s hold before the slew
STEP_STOP = "5 s"
# The bound against seed: the gustiest case (keyhole track, 10 m/s, intensity 0.3) on the unseen
# seeds with other observers than the shipped one: label -> (bandwidth [Hz], controller parameters)
VARIANTS = {"scalar 2000 kg, 20 Hz (before)": (SCALAR_BANDWIDTH, SCALAR),
            "leg_space, 20 Hz": (20.0, {}), "leg_space, 40 Hz": (40.0, {})}
STEP_CHART = "wind_rejection_step.png"
SWITCH_ON = 2.0   # s: the observer switched on in the 10 m/s wind, the loop at its operating point without it


def scheme_scenario(scene, scheme, speed, bandwidth=None, window=True, seed=1, intensity=0.15, step=False,
                    controller=None, on_time=None):
    """The scenario dict of ``scene`` in the realistic loop at ``speed`` m/s with ``scheme``
    (a SCHEMES key), from its operating point and counted from FROM (``window`` False: the
    shipped scene's start at rest and its windows, as the error budget's rows); ``bandwidth`` [Hz]
    overrides the observer's bandwidth, ``controller`` other controller parameters (a VARIANTS
    row's: its mass and model), ``seed`` and ``intensity`` the
    gusts'; ``on_time`` [s] switches the observer on then (from the operating point, the integral
    holding the load until then; counted from 0 s, to STEP_STOP); ``step``: the wind as a
    step onto the calm loop at t = 0 (no operating point; counted from 0 s, to STEP_STOP)."""
    effects = rl.EFFECTS if speed > 0 else rl.LOOPS["calm"]
    wind = {"mean_speed": f"{speed:g} m/s", "seed": seed, "turbulence_intensity": intensity}
    data = rl.variant(scene, effects, "exact", ("moving_base",), {"wind": wind}, window=window,
                      operating_point=window and not step)
    for metric in data["metrics"]:
        if "from" in metric and window:
            metric["from"] = "0 s" if step or on_time is not None else FROM
    if step or on_time is not None:
        data["stop_time"] = STEP_STOP
    changes = copy.deepcopy(SCHEMES[scheme])
    if bandwidth is not None:
        changes["parameters"]["controller"]["observer_bandwidth"] = f"{bandwidth:g} Hz"
    if controller:
        changes["parameters"]["controller"].update(controller)
    if on_time is not None:
        changes["parameters"]["controller"]["observer_on_time"] = f"{on_time:g} s"
    data["fmus"].update(changes.get("fmus", {}))
    for inst, values in changes.get("parameters", {}).items():
        if inst in data["fmus"]:   # calm air has no wind FMU: its anemometer is not there either
            data["fmus"][inst].setdefault("parameters", {}).update(values)
    data["connections"] += [c for c in changes.get("connections", [])
                            if c["from"].split(".")[0] in data["fmus"]]
    data["name"] = (f"{scene}-wind_{speed:g}-{scheme}" + (f"_{bandwidth:g}Hz" if bandwidth is not None else "")
                    + "".join(f"_{v}" for v in (controller or {}).values())
                    + (f"-seed_{seed}-ti_{intensity:g}" if (seed, intensity) != (1, 0.15) else "")
                    + ("-step" if step else "") + (f"-on_{on_time:g}s" if on_time is not None else ""))
    data["description"] = (f"{data['name']}: {scene} in the realistic loop, {speed:g} m/s Kaimal wind (seed "
                           f"{seed}, intensity {intensity:g}), {changes['name']}"
                           + (", the wind a step at t = 0 onto the calm loop." if step else
                              ", from its operating point."))
    return data


def cases():
    """(key, scene, scheme, speed, bandwidth, {seed, intensity, step}) of every run: the
    schemes over the speeds, the observer's bandwidth at 10 m/s, the observer over the unseen
    gusts, and the wind as a step onto the calm slew."""
    out = [((scene, scheme, f"{u:g}"), scene, scheme, u, None, {}) for scene in SCENES for scheme in SCHEMES
           for u in SPEEDS]
    out += [((scene, "bandwidth", f"{b:g}"), scene, "observer", BOUND_SPEED, b, {}) for scene in SCENES
            for b in BOUND_BANDWIDTHS]
    out += [((scene, "gusts", f"{u:g}", f"{ti:g}", f"{seed}"), scene, "observer", u, None,
             {"seed": seed, "intensity": ti}) for scene in SCENES for u in GUST_SPEEDS for ti in INTENSITIES
            for seed in GUST_SEEDS]
    out += [(("telescope_slew", "step", scheme), "telescope_slew", scheme, BOUND_SPEED, None, {"step": True})
            for scheme in ("pid", "observer")]
    out += [(("telescope_slew", "switch_on", "observer"), "telescope_slew", "observer", BOUND_SPEED, None,
             {"on_time": SWITCH_ON})]
    out += [(("keyhole_tracking", "variant", label, f"{seed}"), "keyhole_tracking", "observer", BOUND_SPEED, b,
             {"seed": seed, "intensity": INTENSITIES[-1], "controller": given})
            for label, (b, given) in VARIANTS.items() for seed in GUST_SEEDS]
    out += [(("keyhole_tracking", "more", f"{seed}"), "keyhole_tracking", "observer", BOUND_SPEED, None,
             {"seed": seed, "intensity": INTENSITIES[-1]}) for seed in MORE_SEEDS]
    return out


def run(out="out", jobs=None, address=None, progress=True, selected=None, window=True, ci=False):
    """Run every case not on disk yet (the engine's store resumes); returns {key: the
    pose error's {rms, peak} [µm] and the pointing metric, or None for a run that failed};
    ``ci``: the scenes' short [ci] runs."""
    folder = pathlib.Path(out) / "wind_rejection"
    texts = folder / "scenarios"
    texts.mkdir(parents=True, exist_ok=True)
    store = engine.Store(folder / "runs")
    everything, files, index = [], {}, []
    for key, scene, scheme, speed, bandwidth, *more in selected or cases():
        data = scheme_scenario(scene, scheme, speed, bandwidth, window, **(more[0] if more else {}))
        path = texts / f"{data['name']}.toml"
        path.write_text(rl.toml_text(data))
        scenario, paths, descriptions, values = runner.prepare(path, ci)
        item = spec.sweep_value(scenario, descriptions, "moving_base")
        jobs_here, files_here = engine.prepared_jobs(scenario, paths, values, [("moving_base", {item[0]: {
            item[1]: item[2]}})], keep_record=False)
        everything += jobs_here
        files.update(files_here)
        index += [(key, job) for job in jobs_here]
    with engine.Engine(jobs, address) as eng:
        outcome = eng.run(everything, files, store, progress, name="wind_rejection")
    if outcome.interrupted:
        raise KeyboardInterrupt
    results = {}
    for key, job in index:
        record = store.read(job.key) if store.status(job.key) else {"status": "not run"}
        ok = record.get("status") == "ok"
        m, point = (record["metrics"][rl.METRIC], record["metrics"]["pointing"]) if ok else (None, None)
        results["/".join(key)] = ({"rms": m["rms"], "peak": m["peak"], "pointing_peak": point["peak"],
                                   "loss_q": point[loss_key("Q")], "pointing": point} if m else None)
        if m and key[1] in ("step", "switch_on"):   # the step's pose error against time, for its chart
            t, values = store.series(job.key)[rl.METRIC]
            results["/".join(key)]["series"] = [[round(float(a), 4) for a in t], [float(f"{v:.4g}") for v in values]]
    return results


def loop_model(bandwidth=OBSERVER_BANDWIDTH, controller=None):
    """The LoopModel (controller.design) of the realistic loop with the observer at
    ``bandwidth`` [Hz], the shipped one or a VARIANTS row's ``controller`` parameters, and the
    load cell: as the guard reads it from the shipped scenes."""
    from dataclasses import replace

    from controller import design
    from plant.hexapod.model import StewartParams
    given = {"observer_model": OBSERVER_MODEL, "observer_mass": OBSERVER_MASS, **(controller or {})}
    leg_space = given["observer_model"] == "leg_space"
    return replace(design.REALISTIC, observer_bandwidth=bandwidth, observer_mass=given["observer_mass"],
                   observer_leg_space=leg_space, load_cell=True, load_cell_bandwidth=200.0,
                   observer_model_mean=design.model_mean_leg_mass(StewartParams.paper()) if leg_space else 0.0)


def bandwidth():
    """The observer's design on the realistic plant (controller.design): the highest
    bandwidth with DESIGN_MARGINS on every mode, its margins at the shipped bandwidth (and
    with the reflected mass misjudged by MASS_ERRORS), the VARIANTS' margins and the guard's
    predicted limit of the bandwidth at the 1 ms step."""
    from dataclasses import replace

    from controller import design
    from plant.hexapod.model import StewartParams
    params, gains = StewartParams.paper(), design.default_gains(StewartParams.paper())
    loop = loop_model()
    best = design.design_observer(params, gains, 1e-3, loop, *DESIGN_MARGINS)
    shipped = design.margins(params, gains, 1e-3, loop)
    limit = design.observer_limit(design.modal_masses(params, loop), gains, 1e-3, loop)
    pair = lambda m: [m.modal_phase_margin_deg, m.modal_gain_margin_db]
    variants = {label: pair(design.margins(params, gains, 1e-3, loop_model(b, given)))
                for label, (b, given) in VARIANTS.items()}
    errors = {f"{dm:+g}": pair(design.margins(params, gains, 1e-3, replace(loop, observer_mass=OBSERVER_MASS + dm)))
              for dm in MASS_ERRORS}
    without = design.margins(params, gains, 1e-3, design.REALISTIC)
    return {"design_hz": best.loop.observer_bandwidth, "pm_deg": shipped.modal_phase_margin_deg,
            "gm_db": shipped.modal_gain_margin_db, "crossover_hz": shipped.crossover_hz, "limit_hz": limit,
            "variants": variants, "mass_errors": errors, "without_pm_deg": without.modal_phase_margin_deg,
            "without_gm_db": without.modal_gain_margin_db}


# ------------------------------------------------------------------------ what the docs say
def _peak(s, scene, scheme, speed):
    entry = s["runs"].get(f"{scene}/{scheme}/{speed:g}")
    return None if entry is None else entry["peak"]


def _cell(entry):
    return "failed" if entry is None else f"{fmt(entry['rms'])} / {fmt(entry['peak'])}"


def table(s):
    """Per scene and scheme: RMS / peak pose error per wind speed."""
    lines = ["| scene | scheme | " + " | ".join(f"{u:g} m/s: RMS / peak [µm]" for u in SPEEDS) + " |",
             "|---|---|" + "---|" * len(SPEEDS)]
    for scene in SCENES:
        for scheme, row in SCHEMES.items():
            cells = [_cell(s["runs"].get(f"{scene}/{scheme}/{u:g}")) for u in SPEEDS]
            lines.append(f"| `{scene}` | {row['name']} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def goals(s):
    """The issue's goals, each against today's figure."""
    out = []
    for scene in SCENES:
        best = {k: _peak(s, scene, k, BOUND_SPEED) for k in SCHEMES}
        met = [SCHEMES[k]["name"] for k, v in best.items() if v is not None and v < GOAL]
        out.append(f"- **{scene}, 10 m/s, peak under {GOAL:g} µm** (today {fmt(TODAY[scene][10.0])} µm): "
                   + ", ".join(f"{SCHEMES[k]['name']} {fmt(v) if v is not None else 'failed'} µm"
                               for k, v in best.items())
                   + (f". Met by: {'; '.join(met)}." if met else ". Not met."))
    calm, plain = _peak(s, "telescope_slew", "observer", 0.0), _peak(s, "telescope_slew", "pid", 0.0)
    out.append(f"- **Calm slew keeps what it has** (peak under {TODAY['telescope_slew'][0.0]:g} µm): with the "
               f"observer {fmt(calm) if calm is not None else 'failed'} µm"
               + (" (met" if calm is not None and calm < TODAY["telescope_slew"][0.0] else " (not met")
               + f"; this study's own calm run without it: {fmt(plain) if plain is not None else 'failed'} µm).")
    return "\n".join(out)


def _bound(s, scene, bandwidth):
    entry = s["runs"].get(f"{scene}/bandwidth/{bandwidth:g}")
    return None if entry is None else entry["peak"]


def _ratio(s, scene, speed):
    a, b = _peak(s, scene, "pid", speed), _peak(s, scene, "observer", speed)
    return "failed" if a is None or b is None else f"{a / b:.1f}x"


def pointing(s):
    """What the subreflector's error costs at 10 m/s per scheme: the beam's pointing error
    against Tianma's 3 arcsec, and the aperture efficiency lost at 43 GHz."""
    lines = ["| scene | scheme | pointing peak at 10 m/s [arcsec] (Tianma: within 3) | efficiency lost at Q "
             "43 GHz [%] |", "|---|---|---|---|"]
    for scene in SCENES:
        for scheme, row in SCHEMES.items():
            e = s["runs"].get(f"{scene}/{scheme}/{BOUND_SPEED:g}")
            cells = ["failed", "failed"] if e is None else [fmt(e["pointing_peak"]), fmt(e["loss_q"])]
            lines.append(f"| `{scene}` | {row['name']} | " + " | ".join(cells) + " |")
    return ("The pose error through the Cassegrain optics (plant/telescope/optics.py, the `pointing` metric: "
            "the beam's pointing error from the lateral offset and tilt, the efficiency by Ruze's law at the RMS "
            "path-length error). The hexapod's own share is far inside Tianma's 3 arcsec pointing and costs "
            "little efficiency at 43 GHz (beam ~27 arcsec) even without rejection; the feed support's sway, which "
            "the hexapod cannot correct, is larger ([models.md](models.md#telescope-the-flexible-feed-support)).\n\n"
            + "\n".join(lines))


def _gusts(s, scene, speed, intensity):
    """The peaks [µm] of the unseen gust seeds (None: failed or not run)."""
    return [(s["runs"].get(f"{scene}/gusts/{speed:g}/{intensity:g}/{seed}") or {}).get("peak") for seed in GUST_SEEDS]


def gust_table(s):
    """Per scene, speed and turbulence intensity: the observer's peak pose error over the
    seeds it was not tuned on, the largest, and whether all are under the goal."""
    lines = ["| scene | mean wind | intensity | " + " | ".join(f"seed {k}" for k in GUST_SEEDS)
             + " | largest [µm] | all under 10 µm |", "|---|---|---|" + "---|" * (len(GUST_SEEDS) + 2)]
    for scene in SCENES:
        for u in GUST_SPEEDS:
            for ti in INTENSITIES:
                peaks = _gusts(s, scene, u, ti)
                done = [p for p in peaks if p is not None]
                top = max(done) if done else None
                lines.append(f"| `{scene}` | {u:g} m/s | {ti:g} | " + " | ".join(
                    "failed" if p is None else fmt(p) for p in peaks) + f" | {fmt(top) if top else 'failed'} | "
                    + ("yes" if len(done) == len(peaks) and top < GOAL else "no") + " |")
    return "\n".join(lines)


def _variant(s, label):
    return [(s["runs"].get(f"keyhole_tracking/variant/{label}/{seed}") or {}).get("peak") for seed in GUST_SEEDS]


def variant_table(s):
    """The gustiest case's peaks per unseen seed with the shipped observer and the VARIANTS."""
    rows = ["| observer | margins (linear model) | " + " | ".join(f"seed {k}" for k in GUST_SEEDS)
            + " | largest [µm] |", "|---|---|" + "---|" * (len(GUST_SEEDS) + 1)]
    d = s["design"]
    table = {f"leg_space, {OBSERVER_BANDWIDTH:g} Hz (shipped)": ((d["pm_deg"], d["gm_db"]),
                                                               _gusts(s, "keyhole_tracking", BOUND_SPEED,
                                                                      INTENSITIES[-1]))}
    table.update({label: (d["variants"][label], _variant(s, label)) for label in VARIANTS})
    for label, ((pm, gm), peaks) in table.items():
        done = [p for p in peaks if p is not None]
        rows.append(f"| {label} | {pm:.1f} deg / {gm:.1f} dB | "
                    + " | ".join("failed" if p is None else fmt(p) for p in peaks)
                    + f" | {fmt(max(done)) if done else 'failed'} |")
    return "\n".join(rows)


def _largest(peaks):
    done = [p for p in peaks if p is not None]
    return max(done) if len(done) == len(peaks) else None


def more_seeds_text(s):
    """The gustiest case's tail: its peaks on MORE_SEEDS."""
    peaks = [(s["runs"].get(f"keyhole_tracking/more/{seed}") or {}).get("peak") for seed in MORE_SEEDS]
    if None in peaks:
        return "Some of the runs on more seeds failed."
    worst = max(range(len(peaks)), key=peaks.__getitem__)
    seen = [p for p in _gusts(s, "keyhole_tracking", BOUND_SPEED, INTENSITIES[-1]) if p is not None]
    over = sum(p > 8.0 for p in peaks)
    return (f"The tail: the gustiest case on {len(MORE_SEEDS)} more seeds ({MORE_SEEDS[0]}-{MORE_SEEDS[-1]}), "
            f"peaks {', '.join(fmt(p) for p in peaks)} µm: the largest {fmt(peaks[worst])} µm (seed "
            f"{MORE_SEEDS[worst]}), {over} of them above 8 µm; "
            + (f"under {GOAL:g} µm on all {len(GUST_SEEDS) + len(MORE_SEEDS)} unseen seeds, with "
               f"{fmt(GOAL - max(peaks + seen))} µm to spare on the worst of them" if max(peaks + seen) < GOAL
               else f"not under {GOAL:g} µm on every unseen seed")
            + ": the spread of the gusts' peaks, not their mean, is what the margin has to cover.")


def variant_verdict(s):
    """The shipped observer against the scalar one before it, in the gustiest case."""
    shipped = _largest(_gusts(s, "keyhole_tracking", BOUND_SPEED, INTENSITIES[-1]))
    before = _largest(_variant(s, next(iter(VARIANTS))))
    same = _largest(_variant(s, f"leg_space, {SCALAR_BANDWIDTH:g} Hz"))
    if None in (shipped, before, same):
        return "Some of these runs failed."
    return (f"In the gustiest case the shipped observer's largest peak over the {len(GUST_SEEDS)} unseen seeds is "
            f"{fmt(shipped)} µm, against {fmt(before)} µm with the scalar 2000 kg at {SCALAR_BANDWIDTH:g} Hz "
            f"before it. At the same {SCALAR_BANDWIDTH:g} Hz the leg-space matrix alone gives {fmt(same)} µm: its "
            "gain is the margins it leaves, which let the bandwidth rise "
            f"({s['design']['variants'][next(iter(VARIANTS))][0]:.1f} deg / "
            f"{s['design']['variants'][next(iter(VARIANTS))][1]:.1f} dB for the scalar at {SCALAR_BANDWIDTH:g} Hz, "
            f"{s['design']['pm_deg']:.1f} deg / {s['design']['gm_db']:.1f} dB for the shipped "
            f"{OBSERVER_BANDWIDTH:g} Hz). The peak falls roughly as the bandwidth's square root here; what a "
            "wider observer would still take off (the last row) costs margin: the bound is the loop's delay (the "
            "load cells read one step late under Jacobi, the encoders' sample of delay, the 50 Hz force loop), "
            "which sets how far the observer's band can reach before the margins go. AtLAST budgets 12 µm at 9 m/s.")


def gust_verdict(s):
    """What the unseen gusts say of the shipped configuration, per speed."""
    out = []
    for u in GUST_SPEEDS:
        tops = {(scene, ti): max((p for p in _gusts(s, scene, u, ti) if p is not None), default=None)
                for scene in SCENES for ti in INTENSITIES}
        cells = ", ".join(f"`{scene}` at {ti:g}: {fmt(top) if top else 'failed'} µm"
                          for (scene, ti), top in tops.items())
        met = all(top is not None and top < GOAL for top in tops.values())
        out.append(f"- **{u:g} m/s**, the largest peak over the {len(GUST_SEEDS)} unseen seeds: {cells}. "
                   + ("Under 10 µm on both motions at both intensities." if met else "Not under 10 µm everywhere."))
    return "\n".join(out)


def _step(s, scheme):
    return s["runs"].get(f"telescope_slew/step/{scheme}")


def step_text(s):
    """The wind as a step (a gust front) onto the calm slew: the start's peak with and without
    the observer, against the same loop's steady peak from its operating point."""
    a, b = _step(s, "pid"), _step(s, "observer")
    steady = {k: _peak(s, "telescope_slew", k, BOUND_SPEED) for k in ("pid", "observer")}
    if not (a and b and all(steady.values())):
        return "The step runs failed."
    return (f"The whole mean wind of {BOUND_SPEED:g} m/s arriving at once onto the slew's loop at its calm-air "
            f"operating point (the 5 s hold, counted from 0 s): peak pose error {fmt(a['peak'])} µm without the "
            f"observer, {fmt(b['peak'])} µm with it ({a['peak'] / b['peak']:.1f}x less), against steady peaks from "
            f"the operating point of {fmt(steady['pid'])} and {fmt(steady['observer'])} µm "
            f"({steady['pid'] / steady['observer']:.1f}x). A step holds every frequency: the observer rejects the "
            "part below its bandwidth, and what is faster, the load's first instants before its estimate has "
            "risen, reaches the PID alone. Such a load is a different case from the gusts and has its own figure "
            "and its own shipped scene, `telescope_slew_gust_front`; the other wind scenes start at their "
            "operating point, so that no start step is counted as wind. " + switch_on_text(s))


def switch_on_text(s):
    """The observer switching on mid-run, against the same loop with it on from the start."""
    on = s["runs"].get("telescope_slew/switch_on/observer")
    steady = _peak(s, "telescope_slew", "observer", BOUND_SPEED)
    if not (on and steady):
        return "The switch-on run failed."
    return (f"The observer switching on at {SWITCH_ON:g} s (`observer_on_time`; the loop at its operating point "
            "without it until then, the PID's integral holding the wind's load) is a step from the controller's "
            "side: its estimate rises to the load within its bandwidth while the integral still holds it, so the "
            f"legs briefly push twice the load, and the integral gives it back at its own pace. Peak "
            f"{fmt(on['peak'])} µm (from 0 s) against {fmt(steady)} µm with the observer on from the start: "
            "switching it on in wind needs a bumpless transfer (its estimate started at the integral's hold, as "
            "start_force does at the start); the shipped scene `telescope_slew_observer_switch_on` is this run.")


def step_chart(s, path):
    """The pose error against time after a step load: the wind arriving onto the calm loop, with
    and without the observer (left); the observer switching on in the wind (right)."""
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.4), layout="constrained", sharey=True)
    styles = {"pid": {"color": "tab:blue", "ls": "-"}, "observer": {"color": "tab:green", "ls": (0, (6, 3))}}
    for scheme in ("pid", "observer"):
        entry = _step(s, scheme)
        if entry:
            ax.plot(*entry["series"], lw=1.6, label=SCHEMES[scheme]["name"], **styles[scheme])
    on = s["runs"].get("telescope_slew/switch_on/observer")
    if on:
        bx.plot(*on["series"], lw=1.6, color="tab:purple", label=f"observer switched on at {SWITCH_ON:g} s")
        bx.axvline(SWITCH_ON, color="0.5", lw=1, ls=":")
    top = max([_step(s, k)["peak"] for k in ("pid", "observer") if _step(s, k)] + ([on["peak"]] if on else []))
    for a in (ax, bx):
        draw_marks(a, top=top)
        a.set_yscale("log")
        plain_log_axis(a.yaxis)
        a.grid(which="major", alpha=0.3)
        a.legend(fontsize=9, frameon=False, loc="lower left")
        a.set_xlabel("time [s] (the slew starts at 5 s)")
    ax.set_ylabel("pose position error [µm] (log)")
    ax.set_title(f"a gust front: {BOUND_SPEED:g} m/s arrive at 0 s onto the calm loop", fontsize=10)
    bx.set_title(f"the observer switching on in {BOUND_SPEED:g} m/s wind", fontsize=10)
    fig.suptitle("telescope_slew: loads that arrive as a step", fontsize=11)
    save(fig, path)
    return ax


def bound_table(s):
    rows = ["| observer bandwidth [Hz] | " + " | ".join(f"`{scene}` peak [µm]" for scene in SCENES) + " |",
            "|---|" + "---|" * len(SCENES)]
    for b in BOUND_BANDWIDTHS:
        cells = [s["runs"].get(f"{scene}/bandwidth/{b:g}") for scene in SCENES]
        rows.append(f"| {b:g} | " + " | ".join("failed" if c is None else fmt(c["peak"]) for c in cells) + " |")
    return "\n".join(rows)


def speed_chart(s, path):
    """Peak pose error against mean wind speed, one panel per scene, one line per scheme,
    the 10 µm mark drawn."""
    fig, axes = plt.subplots(1, len(SCENES), figsize=(10, 4.6), layout="constrained", sharey=True)
    styles = {"pid": {"color": "tab:blue", "ls": "-", "marker": "o"},
              "observer": {"color": "tab:green", "ls": (0, (6, 3)), "marker": "s", "mfc": "white", "mew": 1.5},
              "anemometer": {"color": "tab:orange", "ls": (0, (1, 2)), "marker": "^"}}
    top = max(p for e in s["runs"].values() if e for p in [e["peak"]])
    for ax, scene in zip(axes, SCENES):
        for scheme, row in SCHEMES.items():
            points = [(u, _peak(s, scene, scheme, u)) for u in SPEEDS if _peak(s, scene, scheme, u) is not None]
            ax.plot(*zip(*points), lw=1.8, ms=7, label=row["name"], **styles.get(scheme, {}))
        draw_marks(ax, top=top)
        ax.set_yscale("log")
        plain_log_axis(ax.yaxis)
        ax.set_xticks(SPEEDS)
        ax.set_xlabel("mean wind speed [m/s] (Kaimal gusts, 15 % turbulence)")
        ax.set_title(f"{scene}", fontsize=10)
        ax.grid(which="major", alpha=0.3)
    axes[0].set_ylabel(f"peak pose error from {FROM} [µm] (log)")
    fig.suptitle("Realistic loop: peak pose error against wind speed, per rejection scheme", fontsize=11)
    fig.legend(*axes[0].get_legend_handles_labels(), fontsize=9, loc="outside lower center", ncol=2, frameon=False,
               handlelength=4)
    save(fig, path)
    return axes


def report(s, charts=True):
    """docs/wind-rejection.md (and its chart)."""
    d = s["design"]
    name = "wind_rejection_speed.png"
    if charts:
        speed_chart(s, DOCS / "figures" / name)
        step_chart(s, DOCS / "figures" / STEP_CHART)
    lines = [
        "# Wind rejection: under 10 µm in gusty wind", "",
        "Generated by `python -m studies.wind_rejection --docs` from `docs/wind_rejection.json`. The realistic "
        "loop of [realistic_loop.md](realistic_loop.md) (every effect on; moving-base feedforward on the exact base "
        "motion; shipped PID gains), every run from its operating point (the mean wind load held by the "
        "plant, the controller's integral or observer, the load cells; studies/realistic_loop.py "
        f"OPERATING_POINT), pose position error from {FROM} in both scenes, as the shipped scenes count. "
        "`telescope_slew` is the shipped 60 s run; `keyhole_tracking` the 30 s cut with the transit at "
        "16 s. 0 m/s is calm air (no wind FMU). Scenario files: `out/wind_rejection/scenarios/`; shipped: "
        "`telescope_slew_observer`, `keyhole_tracking_observer`.", "",
        "## The disturbance observer", "",
        "The controller's moving-base model already predicts the leg forces the motion needs. Load cells "
        "(`load_cell` FMU) measure what the legs push with; the gap, plus the leg-space mass times the measured "
        "acceleration off the reference, is the external (wind) force per leg, which the controller subtracts "
        "from its command through a 2nd-order Butterworth low-pass Q (`observer_bandwidth`): "
        "d = Q[f_model(ref) + M_o (l - l_ref)'' - f_measured], u = u_PID + f_model - d "
        "(controller/c/observer.c). Load cells, ASSUMED: "
        + ", ".join(f"`{k} = {v}`" for k, v in LOAD_CELL.items())
        + f"; observer mass M_o (`observer_model = \"{OBSERVER_MODEL}\"`, `observer_mass = {OBSERVER_MASS:g}`): "
        "the controller's own leg-space mass matrix M_leg at home (mean diagonal 1847.67 kg) plus 758 kg on "
        "its diagonal, the plant's reflected mass: the plant's matrix, so each leg-space mode (1352-4178 kg) "
        "meets its own mass, and the estimate is Q[wind] up to model error and sampling, not "
        "Q[wind + (M_o - M) e''] as with one scalar for every mode (`observer_model = \"scalar\"`, the "
        "default, as before).", "",
        f"Design (controller.design.design_observer, on the realistic plant of `REALISTIC` with the load cell, "
        "python-control). Issue 29's design (phase margin >= 25 deg, gain margin >= 5 dB on every leg-space "
        "mode, one scalar 2606 kg) gave 8 Hz: under 10 µm on the one gust seed it was tuned on, up to 13 µm on "
        "unseen seeds at turbulence intensity 0.3. Issue 41's first re-tuning (one scalar 2000 kg, between the "
        f"lightest modes and the mean, at 20 Hz) kept only {d['variants'][next(iter(VARIANTS))][0]:.1f} deg "
        f"and {d['variants'][next(iter(VARIANTS))][1]:.1f} dB on the lightest mode, and reached 10.4 µm on an "
        "unseen seed: one scalar is wrong for all but one mode, and the lightest mode's mismatch held the "
        "bandwidth. With the mass per mode, the highest bandwidth keeping phase margin >= "
        f"{DESIGN_MARGINS[0]:g} deg and gain margin >= {DESIGN_MARGINS[1]:g} dB on every mode is "
        f"{d['design_hz']:.2f} Hz; shipped {OBSERVER_BANDWIDTH:g} Hz, where the worst mode keeps "
        f"{d['pm_deg']:.1f} deg and {d['gm_db']:.1f} dB (without the observer: {d['without_pm_deg']:.1f} deg, "
        f"{d['without_gm_db']:.1f} dB), crossing at {d['crossover_hz']:.2f} Hz; with the reflected mass "
        "misjudged by "
        + " and ".join(f"{k} kg {v[0]:.1f} deg / {v[1]:.1f} dB" for k, v in d["mass_errors"].items())
        + f". The guard predicts the loop unstable above {d['limit_hz']:.3g} Hz at the 1 ms step and refuses "
        "such a scene before it runs. These margins are those of the linear model, without the screws' Coulomb "
        "friction, which damps the real loop more; they are modest because the observer feeds the load cells' "
        "force back a step late (what bounds it: the last table below).", "",
        "## Peak and RMS pose error per scheme and wind speed", "", table(s), "",
        f"![peak error against wind speed](figures/{name})", "",
        "## The goals, against today's figures", "", goals(s), "",
        f"## The bound: peak error at {BOUND_SPEED:g} m/s against the observer's bandwidth", "", bound_table(s), "",
        "The slew's peak falls with the bandwidth to its calm-air figure (the calm loop's own error: servo, "
        "sensors, friction), the keyhole track's keeps falling ("
        + ", ".join(f"{fmt(_bound(s, 'keyhole_tracking', b))} µm at {b:g} Hz" for b in BOUND_BANDWIDTHS[2:])
        + "). The bound is the loop's margins, not the load cells: the wind's share falls with the bandwidth, "
        f"while the margins fall (at {OBSERVER_BANDWIDTH:g} Hz {d['pm_deg']:.1f} deg and {d['gm_db']:.1f} dB "
        "are left). More rejection would need less delay in the force path (a faster step, the load cells read "
        "in the same sample) or a wider force loop. "
        f"At 15 m/s the observer cuts the peak {_ratio(s, 'telescope_slew', 15.0)} and "
        f"{_ratio(s, 'keyhole_tracking', 15.0)}, to {fmt(_peak(s, 'telescope_slew', 'observer', 15.0))} and "
        f"{fmt(_peak(s, 'keyhole_tracking', 'observer', 15.0))} µm. Calm air: the keyhole track's peak is "
        f"{fmt(_peak(s, 'keyhole_tracking', 'observer', 0.0))} µm with the observer against "
        f"{fmt(_peak(s, 'keyhole_tracking', 'pid', 0.0))} µm without.", "",
        f"## Gusts it was not tuned on ({BOUND_SPEED:g} and 15 m/s)", "",
        f"The shipped configuration (the observer at {OBSERVER_BANDWIDTH:g} Hz, its mass per mode; its "
        f"bandwidth from the margins above, checked on gust seeds {TUNING_SEEDS[0]}-{TUNING_SEEDS[-1]}: issue "
        "29's 8 Hz on seed 1, issue 41's on seeds 2-9 at intensity 0.3) on seeds "
        f"{GUST_SEEDS[0]}-{GUST_SEEDS[-1]}, which it never met, "
        "at turbulence intensity "
        + " and ".join(f"{ti:g}" for ti in INTENSITIES) + f", both motions, from their operating point, "
        f"counted from {FROM}: peak pose error [µm].", "", gust_table(s), "", gust_verdict(s), "",
        f"Before and after, and the bound against seed: the gustiest case (`keyhole_tracking`, "
        f"{BOUND_SPEED:g} m/s, intensity {INTENSITIES[-1]:g}) on the same unseen seeds with the scalar observer "
        "shipped before, the leg-space one at its bandwidth, and a wider one; each with the worst mode's phase "
        "and gain margin on the linear model.", "", variant_table(s), "", variant_verdict(s), "",
        more_seeds_text(s), "",
        "## A load that arrives as a step", "", step_text(s), "",
        f"![a gust front onto the calm slew](figures/{STEP_CHART})", "",
        "## In the telescope's units", "", pointing(s), ""]
    REPORT.write_text("\n".join(lines))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, help="worker processes (default: all cores)")
    parser.add_argument("--dask", metavar="ADDR", help="an existing Dask scheduler")
    parser.add_argument("--out", default="out")
    parser.add_argument("--docs", action="store_true", help="write docs/wind-rejection.md and its chart")
    parser.add_argument("--from-store", action="store_true", help="only rewrite the docs from the json")
    args = parser.parse_args(argv)
    if args.from_store:
        report(json.loads(STORE.read_text()))
        return
    s = {"design": bandwidth(), "runs": run(args.out, args.jobs, args.dask)}
    print(table(s))
    print(goals(s))
    print(bound_table(s))
    print(gust_table(s))
    print(step_text(s))
    if args.docs:
        STORE.write_text(json.dumps(s, indent=1) + "\n")
        report(s)
        print(f"wrote {REPORT.relative_to(ROOT)}, docs/figures/wind_rejection_speed.png and {STEP_CHART}")


if __name__ == "__main__":
    sys.exit(main())

"""The kit's FMUs, one row each: the one table that names them for every layer.

One name per FMU: its key (what a scenario file writes, ``fmu = "telescope"``) gives the
pythonfmu script ``fmu_src/<key>_fmu.py``, the native model file
``fmu_src/native/<key>_fmu.c``, and the model identifier, the FMU's file name and the
Python class: the key in CamelCase (``telescope`` -> ``Telescope``,
``mechanism3t_plant`` -> ``Mechanism3TPlant``). The other columns say what only this FMU
has: the C constants its native build generates (``fmu_src.native_build``), the inputs a
scenario may leave unconnected, the outputs that follow an input within a step, and the
loop a controller closes (which the guard, ``scenarios.runs.flags``, reads).
"""
from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class FMU:
    key: str
    constants: str = ""          # fmu_src.native_build: the generator of its C constants ("": none)
    optional_inputs: tuple = ()  # inputs that may stay unconnected, held at their start value
    output_derivatives: dict = field(default_factory=dict)   # FMI 3: output -> the output it is the derivative of

    @property
    def script(self):
        """The pythonfmu script's module name, fmu_src/<script>.py."""
        return f"{self.key}_fmu"

    @property
    def identifier(self):
        """modelIdentifier, the FMU's file name and the script's class name."""
        return self.key.title().replace("_", "")

    @property
    def c_file(self):
        """The native model file in fmu_src/native/."""
        return f"{self.key}_fmu.c"


# The telescope computes its base's and reference's pose, rate and acceleration and its axes'
# angle, rate and acceleration analytically at every communication point: FMI 3 declares
# them as derivatives (a Float64's derivative attribute) and fmi3GetOutputDerivatives
# answers from them: base_pose has orders 1 and 2, base_rate order 1, base_acc none.
FMUS = (
    FMU("hexapod_plant", constants="hexapod_plant", optional_inputs=("platform_wrench",)),
    FMU("telescope", constants="telescope", optional_inputs=("support_load",), output_derivatives={
        "base_rate": "base_pose", "base_acc": "base_rate", "reference_rate": "reference_pose",
        "reference_acc": "reference_rate", "axis_rate": "axis", "axis_acc": "axis_rate",
        "command_base_rate": "command_base_pose", "command_base_acc": "command_base_rate"}),
    FMU("leg_controller", constants="leg_controller", optional_inputs=("leg_force_measured", "wind_speed")),
    FMU("mechanism3t_plant", constants="mechanism3t"),
    FMU("slider_controller", constants="mechanism3t"),
    FMU("leg_sensor", constants="leg_sensor"),
    FMU("base_sensor"),
    FMU("wind"),
    FMU("load_cell"),
)
BY_KEY = {f.key: f for f in FMUS}
BY_IDENTIFIER = {f.identifier: f for f in FMUS}
KEYS = tuple(BY_KEY)
SCRIPTS = tuple(f.script for f in FMUS)

# controller FMU -> the loop it closes, which the guard (scenarios.runs.flags) predicts and watches
# from this table alone: the plant FMU it drives; its force output and the plant input that
# output feeds; the plant output it measures and its own input of it (directly or through a
# sensor of LOOP_SENSORS); its gains and force-limit parameters; its reference input fed by
# a telescope (the motion the loop's masses are taken along; None: the controller makes its
# reference from its own ``motion`` parameters) and the variable of it whose changes excite
# the loop (``excitation``: the reference it tracks); the plant's force limit parameter (the plant
# clips its force input there; 0: none), stroke parameter (half stroke about the home value)
# and the LoopModel fields (controller.design) its parameters give; a disturbance observer's
# LoopModel fields from the controller's parameters (``observer``) and its force input
# (``force_measured``), fed by a sensor of LOAD_CELLS.
CONTROL_LOOPS: dict[str, dict[str, Any]] = {
    "leg_controller": {
        "plant": "hexapod_plant", "force": "leg_force", "plant_force": "leg_force",
        "measured": "leg_length", "plant_measured": "leg_length", "gains": ("kp", "ki", "kd"),
        "limit": "force_limit", "reference": "reference_pose", "motion": (), "excitation": "reference_pose",
        "plant_limit": "actuator_force_limit", "stroke": "stroke",
        "loop_model": {"reflected_mass": "reflected_mass", "actuator_bandwidth": "actuator_bandwidth",
                       "viscous_friction": "viscous_friction"},
        "observer": {"observer_bandwidth": "observer_bandwidth", "observer_mass": "observer_mass",
                     "observer_leg_space": "observer_model"},
        "force_measured": "leg_force_measured"},
    "slider_controller": {
        "plant": "mechanism3t_plant", "force": "slider_force", "plant_force": "slider_force",
        "measured": "slider_position", "plant_measured": "slider_position", "gains": ("kp", "ki", "kd"),
        "limit": "force_limit", "reference": None, "motion": ("initial_position", "amplitude", "omega"),
        "excitation": "reference_position",
        "plant_limit": None, "stroke": None, "loop_model": {}},
}
# sensor FMU -> (its input of the plant's measured output, its measured output, the LoopModel
# fields its parameters give): a sensor between plant and controller in a loop of CONTROL_LOOPS
LOOP_SENSORS = {"leg_sensor": ("leg_length", "measured_length", {"rate_cutoff": "rate_cutoff",
                                                                  "delay_steps": "delay_steps"})}
# force sensor FMU -> the LoopModel fields its parameters give (a sensor between the plant's
# delivered force and a controller's ``force_measured`` input)
LOAD_CELLS = {"load_cell": {"load_cell_bandwidth": "bandwidth", "load_cell_delay_steps": "delay_steps"}}
# FMU -> {output: the inputs it follows within one communication step, with no state between
# them (direct feedthrough; the modelDescriptions declare them: output_dependencies)}: a cycle of
# connections through these alone is an algebraic loop that the master cannot solve, and an
# output wired back into such an input of its own FMU measures nothing (_check_wiring). A
# sensor's delay line counts as no state: it holds no dynamics of what it measures.
# No telescope row: its support_load input reaches base_* only through the support modes' state
# (fmu_src/telescope_fmu.py), so wind -> telescope -> wind is no algebraic loop.
ALL = "*"
FEEDTHROUGH = {
    "leg_sensor": {"measured_length": ("leg_length",), "estimated_rate": ("leg_length",)},
    "base_sensor": {"base_pose": ALL, "base_rate": ALL, "base_acc": ALL},
    # the observer's load-cell input acts one step later (controller/c/observer.c)
    "leg_controller": {out: ("reference_pose", "reference_rate", "reference_acc", "leg_length", "leg_rate",
                             "base_pose", "base_rate", "base_acc")
                       for out in ("leg_force", "feedforward_force", "disturbance_estimate")},
    "slider_controller": {"slider_force": ("slider_position", "slider_rate")},
    "wind": {"platform_wrench": ("base_pose",)},
    "hexapod_plant": {"leg_force_actual": ("leg_force",)},
    # its filter's new value and a delay of 0 reach the output in the step: it starts at the plant's force
    "load_cell": {"measured_force": ("leg_force",)},
}
OPTIONAL_INPUTS = {f.key: f.optional_inputs for f in FMUS if f.optional_inputs}


def output_dependencies(key, output, inputs):
    """The names of ``inputs`` (an FMU's inputs, in its order: FMI 2 scalars ``name[k]`` or
    FMI 3 arrays) that its output ``output`` follows within a step (FEEDTHROUGH): each
    element of an output follows every element of the inputs its row names; [] for an output
    with no direct feedthrough (declared ``dependencies=""``: FMI reads a missing attribute as
    every input, and an importer such as OMSimulator then finds algebraic loops that are not)."""
    follows = FEEDTHROUGH.get(key, {}).get(output.split("[")[0], ())
    return [name for name in inputs if follows == ALL or name.split("[")[0] in follows]

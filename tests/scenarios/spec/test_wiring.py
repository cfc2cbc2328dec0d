"""Wiring that cannot be meant is refused before anything runs, naming its connections
(spec.check_wiring): an output wired back into its own FMU's input with no state between
them, an algebraic loop of such outputs, and a control loop that does not measure its
plant. Each of these once ran 0.15 s and ended in a stroke error that named neither
connection. The truth: the realistic slew's own wiring, edited one connection at a time."""
import pytest

import movingbase
from fmu_src import catalogue
from scenarios.runs import campaign, runner

REALISTIC = (runner.SHIPPED / "telescope_slew_realistic.toml").read_text()
PLANT_TO_SENSOR = 'from = "plant.leg_length"\nto = "sensor.leg_length"'


def _refused(tmp_path, text, *expected):
    path = tmp_path / "wired.toml"
    path.write_text(text)
    with pytest.raises(movingbase.ScenarioError) as refused:
        movingbase.run(path, ci=True, progress=False)
    message = str(refused.value)
    for part in expected:
        assert part in message, message
    return message


def test_a_sensor_wired_into_itself_is_refused_naming_the_connection(tmp_path):
    text = REALISTIC.replace(PLANT_TO_SENSOR, 'from = "sensor.measured_length"\nto = "sensor.leg_length"')
    _refused(tmp_path, text, "connections: sensor.measured_length -> sensor.leg_length wires an output back into its "
             "own FMU's input", "leg_sensor's measured_length follows its leg_length within a step")


def test_sensors_in_a_ring_are_an_algebraic_loop(tmp_path):
    ring = REALISTIC.replace(PLANT_TO_SENSOR, 'from = "sensor2.measured_length"\nto = "sensor.leg_length"\n'
                             '[[connections]]\nfrom = "sensor.measured_length"\nto = "sensor2.leg_length"')
    ring = ring.replace("[fmus.controller]", '[fmus.sensor2]\nfmu = "leg_sensor"\n\n[fmus.controller]')
    ring = ring.replace('from = "sensor.measured_length"\nto = "controller.leg_length"',
                        'from = "sensor.measured_length"\nto = ["controller.leg_length"]')
    message = _refused(tmp_path, ring, "an algebraic loop", "that the master cannot solve")
    assert "sensor2.measured_length -> sensor.leg_length" in message
    assert "sensor.measured_length -> sensor2.leg_length" in message


def _with_second_plant(text):
    """``text`` with a second hexapod 'plant2' on the same base, driven by the controller's
    feedforward force (so every input of it is fed)."""
    text = text.replace("[fmus.sensor]", '[fmus.plant2]\nfmu = "hexapod_plant"\nparameters = { initial_pose = '
                        '"@base.reference_pose" }\n\n[fmus.sensor]')
    for base in ("base_pose", "base_rate", "base_acc"):
        text = text.replace(f'to = ["plant.{base}", "controller.{base}"]',
                            f'to = ["plant.{base}", "controller.{base}", "plant2.{base}"]')
    return text + '\n[[connections]]\nfrom = "controller.feedforward_force"\nto = "plant2.leg_force"\n'


def test_a_loop_that_does_not_measure_its_plant_is_refused(tmp_path):
    """The sensor reads a second hexapod's legs: the controller drives 'plant' blind, and
    plant.leg_length goes nowhere."""
    other = _with_second_plant(REALISTIC.replace(PLANT_TO_SENSOR,
                                                 'from = "plant2.leg_length"\nto = "sensor.leg_length"'))
    _refused(tmp_path, other, "the loop of 'controller' (its leg_force drives plant.leg_force) does not measure its "
             "plant: controller.leg_length is fed by plant2.leg_length -> sensor.leg_length, then "
             "sensor.measured_length -> controller.leg_length, not by plant.leg_length",
             "; plant.leg_length is connected to nothing")


@pytest.mark.parametrize("first", [1, 2])
def test_a_loop_measuring_only_some_legs_is_refused_in_any_order(tmp_path, first):
    """Leg 1 wired element-wise from the plant, legs 2-6 from another hexapod: refused
    whichever connection is listed first (a check of the first feed alone passed it)."""
    rows = {k: f'from = "{"plant" if k == 1 else "plant2"}.leg_length[{k}]"\nto = "sensor.leg_length[{k}]"\n'
            for k in range(1, 7)}
    order = [first, *(k for k in rows if k != first)]
    split = "[[connections]]\n".join(rows[k] for k in order)
    message = _refused(tmp_path, _with_second_plant(REALISTIC.replace(PLANT_TO_SENSOR, split)),
                       "does not measure its plant: controller.leg_length[2], controller.leg_length[3], "
                       "controller.leg_length[4], controller.leg_length[5], controller.leg_length[6] are not fed by "
                       "plant.leg_length (directly or through a sensor): controller.leg_length[2] is fed by "
                       "plant2.leg_length[2] -> sensor.leg_length[2], then sensor.measured_length -> "
                       "controller.leg_length", "; plant.leg_length[2], plant.leg_length[3], plant.leg_length[4], "
                       "plant.leg_length[5], plant.leg_length[6] are connected to nothing")
    assert "controller.leg_length[1]" not in message and "plant.leg_length[1]" not in message


def test_a_sensor_input_held_by_a_parameter_is_named(tmp_path):
    """The sensor's leg lengths set to a constant in its parameters, not wired from the
    plant: the refusal names the parameter as what the loop measures."""
    text = REALISTIC.replace(f"[[connections]]\n{PLANT_TO_SENSOR}\n", "")
    text = text.replace("seed = 1 }", 'seed = 1, leg_length = ["3.1 m", "3.1 m", "3.1 m", "3.1 m", "3.1 m", '
                        '"3.1 m"] }', 1)
    _refused(tmp_path, text, "does not measure its plant: controller.leg_length is fed by "
             "fmus.sensor.parameters.leg_length, then sensor.measured_length -> controller.leg_length, not by "
             "plant.leg_length", "; plant.leg_length is connected to nothing")


def test_the_3t_mechanism_loop_is_checked_too(tmp_path):
    """The same rule from the catalogue alone (CONTROL_LOOPS), for the slider loop: its
    controller measures a second mechanism while driving the first."""
    text = (runner.SHIPPED / "mechanism3t_paper.toml").read_text()
    text = text.replace('from = "plant.slider_position"', 'from = "plant2.slider_position"')
    text = text.replace("[fmus.controller]", '[fmus.plant2]\nfmu = "mechanism3t_plant"\nparameters = { slider_force = '
                        '["0 N", "0 N", "0 N"] }\n\n[fmus.controller]')
    _refused(tmp_path, text, "the loop of 'controller' (its slider_force drives plant.slider_force) does not measure "
             "its plant: controller.slider_position is fed by plant2.slider_position -> controller.slider_position, "
             "not by plant.slider_position", "; plant.slider_position is connected to nothing")


def test_wiring_is_judged_on_valid_connections_only(tmp_path):
    """Lengths and rates swapped into the controller: the unit mismatch is told, and no
    loop refusal built on a connection that is itself refused."""
    text = REALISTIC.replace('from = "sensor.measured_length"\nto = "controller.leg_length"',
                             'from = "sensor.estimated_rate"\nto = "controller.leg_length"')
    text = text.replace('from = "sensor.estimated_rate"\nto = "controller.leg_rate"',
                        'from = "sensor.measured_length"\nto = "controller.leg_rate"')
    message = _refused(tmp_path, text, "incompatible: sensor.estimated_rate[1] (Real, m/s) -> controller.leg_length[1]")
    assert "does not measure" not in message


def test_every_shipped_scenario_and_campaign_is_wired_as_meant():
    for path in sorted(runner.SHIPPED.glob("*.toml")):
        prepared = runner.prepare_loaded(movingbase.load_scenario(path), None, None)
        assert prepared[0].connections
    for path in sorted((runner.SHIPPED.parent / "campaigns").glob("*.toml")):
        assert campaign.load(path).cases


def test_the_feedthrough_table_names_real_outputs_and_inputs():
    """catalogue.FEEDTHROUGH against every FMU's modelDescription: a renamed variable would
    leave a loop unchecked."""
    import re

    from fmpy import read_model_description
    for fmu, outputs in catalogue.FEEDTHROUGH.items():
        md = read_model_description(str(movingbase.fmus(fmu)[fmu]))
        kinds = {re.sub(r"\[\d+\]$", "", v.name): v.causality for v in md.modelVariables}
        for output, inputs in outputs.items():
            assert kinds.get(output) == "output", (fmu, output)
            assert inputs == catalogue.ALL or all(kinds.get(i) == "input" for i in inputs), (fmu, inputs)

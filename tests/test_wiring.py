"""Wiring that cannot be meant is refused before anything runs, naming its connections
(spec._check_wiring): an output wired back into its own FMU's input with no state between
them, an algebraic loop of such outputs, and a control loop that does not measure its
plant. Each of these once ran 0.15 s and ended in a stroke error that named neither
connection. The truth: the realistic slew's own wiring, edited one connection at a time."""
import pytest

import movingbase
from movingbase.scenarios import campaign, runner

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


def test_a_loop_that_does_not_measure_its_plant_is_refused(tmp_path):
    """The sensor reads a second hexapod's legs: the controller drives 'plant' blind, and
    plant.leg_length goes nowhere."""
    other = REALISTIC.replace(PLANT_TO_SENSOR, 'from = "plant2.leg_length"\nto = "sensor.leg_length"')
    other = other.replace("[fmus.sensor]", '[fmus.plant2]\nfmu = "hexapod_plant"\nparameters = { initial_pose = '
                          '"@base.reference_pose" }\n\n[fmus.sensor]')
    other = other.replace('to = ["plant.base_pose", "controller.base_pose"]',
                          'to = ["plant.base_pose", "controller.base_pose", "plant2.base_pose"]')
    other = other.replace('to = ["plant.base_rate", "controller.base_rate"]',
                          'to = ["plant.base_rate", "controller.base_rate", "plant2.base_rate"]')
    other = other.replace('to = ["plant.base_acc", "controller.base_acc"]',
                          'to = ["plant.base_acc", "controller.base_acc", "plant2.base_acc"]')
    other += '\n[[connections]]\nfrom = "controller.feedforward_force"\nto = "plant2.leg_force"\n'
    _refused(tmp_path, other, "the loop of 'controller' (its leg_force drives plant.leg_force) does not measure its "
             "plant", "controller.leg_length is fed by", "not by plant.leg_length",
             "plant.leg_length is connected to nothing")


def test_every_shipped_scenario_and_campaign_is_wired_as_meant():
    for path in sorted(runner.SHIPPED.glob("*.toml")):
        prepared = runner.prepare_loaded(movingbase.load_scenario(path), None, None)
        assert prepared[0].connections
    for path in sorted((runner.SHIPPED.parent / "campaigns").glob("*.toml")):
        assert campaign.load(path).cases


def test_the_feedthrough_table_names_real_outputs_and_inputs():
    """spec.FEEDTHROUGH against every FMU's modelDescription: a renamed variable would
    leave a loop unchecked."""
    import re
    from fmpy import read_model_description
    from movingbase.scenarios import spec
    for fmu, outputs in spec.FEEDTHROUGH.items():
        md = read_model_description(str(movingbase.fmus(fmu)[fmu]))
        kinds = {re.sub(r"\[\d+\]$", "", v.name): v.causality for v in md.modelVariables}
        for output, inputs in outputs.items():
            assert kinds.get(output) == "output", (fmu, output)
            assert inputs == spec._ALL or all(kinds.get(i) == "input" for i in inputs), (fmu, inputs)

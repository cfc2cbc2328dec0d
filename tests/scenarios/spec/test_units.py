"""The unit table of scenario files against the units' definitions (scipy.constants, not
our own numbers), and a parameter written in every unit the format accepts, bound
through a shipped scenario as a user would write it."""
import pytest
from scipy import constants

from fmu_src import catalogue
from scenarios import spec
from scenarios.cosim.fmi import unpack
from scenarios.runs import runner
from scenarios.spec import units
from scenarios.spec.units import UnitError, to_si

# unit -> (SI value of one unit, SI dimension), from the definitions
DEFINITIONS = {
    "s": (1.0, "s"), "ms": (constants.milli, "s"), "us": (constants.micro, "s"), "min": (constants.minute, "s"),
    "h": (constants.hour, "s"),
    "m": (1.0, "m"), "mm": (constants.milli, "m"), "um": (constants.micro, "m"),
    "rad": (1.0, "rad"), "deg": (constants.degree, "rad"), "mrad": (constants.milli, "rad"),
    "urad": (constants.micro, "rad"),
    "N": (1.0, "N"), "kN": (constants.kilo, "N"),
    "m/s": (1.0, "m/s"), "mm/s": (constants.milli, "m/s"),
    "rad/s": (1.0, "rad/s"), "deg/s": (constants.degree, "rad/s"),
    "rad/s2": (1.0, "rad/s2"), "deg/s2": (constants.degree, "rad/s2"),
    "m/s2": (1.0, "m/s2"), "mm/s2": (constants.milli, "m/s2"),
    "N/m": (1.0, "N/m"), "N/(m.s)": (1.0, "N/(m.s)"), "N.s/m": (1.0, "N.s/m"),
    "Hz": (1.0, "1/s"),
    "kg": (1.0, "kg"), "g": (constants.gram, "kg"), "kg.m2": (1.0, "kg.m2"), "N.m": (1.0, "N.m"),
    "ppm": (constants.micro, "1"), "%": (constants.centi, "1"),
    "arcsec": (constants.arcsec, "rad"), "arcmin": (constants.arcmin, "rad"),
}


def test_every_unit_has_a_definition_here():
    assert set(units.UNITS) == set(DEFINITIONS)


@pytest.mark.parametrize("unit", sorted(DEFINITIONS))
def test_each_unit_converts_by_its_definition(unit):
    factor, dimension = DEFINITIONS[unit]
    assert to_si(f"2.5 {unit}", dimension) == pytest.approx(2.5 * factor, rel=1e-15)
    assert to_si(f"-4e-3{unit}", dimension) == pytest.approx(-4e-3 * factor, rel=1e-15)
    other = "s" if dimension != "s" else "m"
    with pytest.raises(UnitError) as error:
        to_si(f"2.5 {unit}", other)
    assert f"is in {dimension}; expected a quantity in {other} (" in str(error.value)


def test_bare_numbers_are_si_and_other_forms_are_refused():
    assert to_si(3) == 3.0 and to_si("0.25", "rad") == 0.25
    for bad, problem in ((True, "expected a number or quantity"), ("deg 30", "cannot read quantity"),
                         ([1], "expected a number or a quantity string"), ("1e999 m", "is not a finite number")):
        with pytest.raises(UnitError, match=problem):
            to_si(bad, "m")


@pytest.mark.parametrize("written, unit", [
    ("2 µm", "um"), ("2 μm", "um"), ("2 um", "um"), ("2 µrad", "urad"), ("2 μs", "us"),
    ("2°", "deg"), ("2 °", "deg"), ("2 Deg", "deg"), ("2 DEG", "deg"), ("2 degree", "deg"), ("2 degrees", "deg"),
    ("2 Radians", "rad"), ("2 °/s", "deg/s"), ("2 °/s2", "deg/s2"), ("2 seconds", "s"), ("2 metres", "m"),
    ("2 Millimeters", "mm")])
def test_the_obvious_spellings_are_the_units_they_spell(written, unit):
    # "60°", "60 Deg" and "60 degree" were refused; "µm" had an entry of its own that µ -> u made
    # unreachable: every spelling of micro is one path to the u unit now
    factor, dimension = DEFINITIONS[unit]
    assert to_si(written, dimension) == pytest.approx(2 * factor, rel=1e-15)


def test_si_case_is_kept_where_it_tells_units_apart():
    assert to_si("1 Mm", "m") == constants.mega and to_si("1 Ms", "s") == constants.mega   # not milli
    for written in ("1 MS", "1 n", "1 kdeg", "1 kmin", "1 Kg"):    # no unit S; prefixes of factor-1 units only
        with pytest.raises(UnitError, match="unknown unit"):
            to_si(written)


@pytest.mark.parametrize("written, dimension, si", [
    ("78.2 ppm", "1", 78.2 * constants.micro), ("2 kHz", "1/s", 2 * constants.kilo), ("5 nm", "m", 5 * constants.nano),
    ("3 kN.m", "N.m", 3 * constants.kilo), ("2 mg", "kg", 2 * constants.milli * constants.gram),
    ("12 arcsec", "rad", 12 * constants.arcsec), ("95.1 %", "1", 0.951), ("7 µN/m", "N/m", 7 * constants.micro),
    ("1.5 km/s", "m/s", 1.5 * constants.kilo), ("4 GHz", "1/s", 4 * constants.giga),
    ("250 ps", "s", 250 * constants.pico)])
def test_what_the_kit_prints_and_si_prefixes_read_back(written, dimension, si):
    # "78.2 ppm" (the budget's own output) and "2 kHz" for a bandwidth were refused (issue 38)
    assert to_si(written, dimension) == pytest.approx(si, rel=1e-15)


@pytest.mark.parametrize("value, taken", [(60, 60.0), ("60", 60.0), (" 100 ", 100.0), (-2, -2.0)])
def test_a_bare_number_is_si_and_a_refusal_of_one_says_what_to_write(value, taken):
    # 60 for an elevation was refused with no hint to write "60 deg": the rule (a bare number
    # is SI) is said with the refusal, and the unit to write
    import movingbase
    with pytest.raises(spec.ScenarioError, match=f"start_elevation: {value!r} is outside the range .*"
                                                 rf"\(a bare number is SI: {taken:g} rad; for deg write "
                                                 f"'{taken:g} deg'\\)"):
        runner.prepare_loaded(movingbase.load_scenario("telescope_slew", set={"base.start_elevation": value}))
    bound = runner.prepare_loaded(movingbase.load_scenario("telescope_slew", set={
        "base.start_elevation": 1.0, "base.target_elevation": "60°", "base.lever_arm": 20}))[3]
    assert bound["base"]["start_elevation"] == 1.0 and bound["base"]["lever_arm"] == 20.0
    assert bound["base"]["target_elevation"] == pytest.approx(constants.pi / 3)


# dimension -> (shipped scenario, instance, parameter) that a user may set in that dimension
WRITTEN_IN = {
    "s": ("telescope_slew", "base", "start_delay"),
    "m": ("telescope_slew", "base", "lever_arm"),
    "rad": ("telescope_slew", "base", "start_azimuth"),
    "rad/s": ("telescope_slew", "base", "az_rate_max"),
    "rad/s2": ("telescope_slew", "base", "el_acc_max"),
    "N": ("telescope_slew", "controller", "force_limit"),
    "N/m": ("telescope_slew", "controller", "kp"),
    "N/(m.s)": ("telescope_slew", "controller", "ki"),
    "N.s/m": ("telescope_slew", "controller", "kd"),
    "m/s": ("paper_fixed_base", "controller", "base_rate"),      # inputs set as values there
    "m/s2": ("paper_fixed_base", "controller", "base_acc"),
    "kg": ("telescope_slew", "plant", "payload_mass_error"),
    "kg.m2": ("telescope_slew", "plant", "payload_inertia_error"),
    "1": ("telescope_slew", "controller", "wind_feedforward"),
}
NO_VARIABLE = {"1/s", "N.m"}   # no FMU parameter is in 1/s or N.m: refused with the unit expected


@pytest.fixture(scope="module")
def fmu_descriptions(fmus):
    return lambda scenario: {inst: unpack(fmus[catalogue.BY_KEY[f].script])[0] for inst, f in scenario.fmus.items()}


def test_every_dimension_is_covered():
    assert set(WRITTEN_IN) | NO_VARIABLE == {d for _, d in DEFINITIONS.values()}


@pytest.mark.parametrize("unit", sorted(u for u, (_, d) in DEFINITIONS.items() if d in WRITTEN_IN))
def test_a_parameter_written_in_each_unit_reaches_the_fmu_in_si(unit, fmu_descriptions):
    factor, dimension = DEFINITIONS[unit]
    name, inst, variable = WRITTEN_IN[dimension]
    scenario = spec.load(runner.resolve(name))
    written = f"0.75 {unit}"
    vector = variable in ("base_rate", "base_acc", "payload_inertia_error")
    scenario.parameters[inst][variable] = [written] + [0] * (2 if variable == "payload_inertia_error" else 5) \
        if vector else written
    values = spec.bind(scenario, fmu_descriptions(scenario))
    assert values[inst][f"{variable}[1]" if vector else variable] == pytest.approx(0.75 * factor, rel=1e-15)


def test_a_unit_of_a_dimension_no_variable_has_is_refused_naming_the_expected_one(fmu_descriptions):
    scenario = spec.load(runner.resolve("mechanism3t_paper"))
    inst = next(i for i, f in scenario.fmus.items() if f == "slider_controller")
    scenario.parameters[inst]["omega"] = "0.08 Hz"
    with pytest.raises(spec.ScenarioError, match=rf"fmus\.{inst}\.parameters\.omega: '0\.08 Hz' is in 1/s; "
                       r"expected a quantity in rad/s \(rad/s, deg/s\)$"):
        spec.bind(scenario, fmu_descriptions(scenario))

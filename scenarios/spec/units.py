"""Quantities as people write them in scenario files ("1 ms", "30 deg", "2681.5 mm"),
converted to SI at the edge. The rule: a bare number is SI (seconds, metres, radians,
newtons), as it is to the FMUs and in Python (numbers from numpy), and a value refused
for its range says so with the unit to write ("60" for an angle: "write '60 deg'",
scenarios.spec); the unit a variable declares is always accepted for it ("1.225 kg/m3"
for a density in kg/m3). Units are written as in UNITS, in SI case ("mm" is not "Mm"), or as
an SI prefix of PREFIXES before a unit of UNITS whose factor is 1 ("2 kHz", "5 nm", "3 kN.m");
the micro prefix may be written u, µ (micro sign) or μ (Greek mu), and the unit words of WORDS
in any case, singular or plural ("60°", "60 Deg", "60 degrees"). Every unit the kit prints
reads back ("78.2 ppm", "12 arcsec", "95.1 %")."""
import math
import re

# unit -> (SI factor, dimension)
UNITS = {
    "s": (1.0, "s"), "ms": (1e-3, "s"), "us": (1e-6, "s"), "min": (60.0, "s"), "h": (3600.0, "s"),
    "m": (1.0, "m"), "mm": (1e-3, "m"), "um": (1e-6, "m"),
    "rad": (1.0, "rad"), "deg": (math.pi / 180, "rad"), "mrad": (1e-3, "rad"), "urad": (1e-6, "rad"),
    "N": (1.0, "N"), "kN": (1e3, "N"),
    "m/s": (1.0, "m/s"), "mm/s": (1e-3, "m/s"),
    "rad/s": (1.0, "rad/s"), "deg/s": (math.pi / 180, "rad/s"),
    "rad/s2": (1.0, "rad/s2"), "deg/s2": (math.pi / 180, "rad/s2"),
    "m/s2": (1.0, "m/s2"), "mm/s2": (1e-3, "m/s2"),
    "N/m": (1.0, "N/m"), "N/(m.s)": (1.0, "N/(m.s)"), "N.s/m": (1.0, "N.s/m"),
    "Hz": (1.0, "1/s"),
    "kg": (1.0, "kg"), "g": (1e-3, "kg"), "kg.m2": (1.0, "kg.m2"), "N.m": (1.0, "N.m"),
    "ppm": (1e-6, "1"), "%": (1e-2, "1"),
    "arcsec": (math.pi / 648000, "rad"), "arcmin": (math.pi / 10800, "rad"),
}
PREFIXES = {"p": 1e-12, "n": 1e-9, "u": 1e-6, "m": 1e-3, "k": 1e3, "M": 1e6, "G": 1e9}
# unit words, in any case and singular or plural, and the units they stand for
WORDS = {"°": "deg", "degree": "deg", "degrees": "deg", "deg": "deg", "rad": "rad", "radian": "rad", "radians": "rad",
         "°/s": "deg/s", "degree/s": "deg/s", "degrees/s": "deg/s", "°/s2": "deg/s2",
         "second": "s", "seconds": "s", "sec": "s", "millisecond": "ms", "milliseconds": "ms",
         "meter": "m", "meters": "m", "metre": "m", "metres": "m",
         "millimeter": "mm", "millimeters": "mm", "millimetre": "mm", "millimetres": "mm"}
_QUANTITY = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(°(?:/s2?)?|\S+)?\s*$")


_MICRO = re.compile("^[\u00b5\u03bc]")
# characters that look like a number's but are not (pasted from documents), and what to write
_LOOKALIKES = {"\u2212": " (the minus sign '\u2212' is not '-')", "\u2013": " (the dash '\u2013' is not '-')",
               ",": " (a decimal point, not a comma)", "_": " (digits without '_')"}


class UnitError(ValueError):
    """A quantity with an unknown unit or a unit of the wrong dimension."""


def lookup(unit):
    """(SI factor, dimension) of a unit as UNITS spells it, or an SI prefix before a unit of
    factor 1 (or the gram); None if it is neither."""
    if unit in UNITS:
        return UNITS[unit]
    base = UNITS.get(unit[1:])
    if unit[:1] in PREFIXES and base is not None and (base[0] == 1.0 or unit[1:] == "g"):
        return PREFIXES[unit[0]] * base[0], base[1]
    return None


def units_of(dimension):
    """The units written for an SI dimension, e.g. 'rad, deg, mrad, urad' for "rad"."""
    return ", ".join(u for u, (_, d) in UNITS.items() if d == dimension) or dimension


def spelled(unit):
    """The UNITS name of a unit as written: micro as u ("µm", "μm"), a unit word in any case
    or number ("Deg", "degrees", "°"); anything else as it is (refused if not in UNITS)."""
    unit = _MICRO.sub("u", unit)
    return WORDS.get(unit.lower(), unit) if lookup(unit) is None else unit


def split(value):
    """(number, unit or None) of a quantity string; UnitError if it is not one."""
    match = _QUANTITY.match(value)
    if not match and re.match(r"\s*[-+]?(nan|inf(inity)?)\b", value, re.IGNORECASE):
        raise UnitError(f"{value!r} is not a finite number")
    if not match:
        hint = next((h for c, h in _LOOKALIKES.items() if c in value), "")
        raise UnitError(f"cannot read quantity {value!r}: write '<number> <unit>'{hint}")
    return float(match.group(1)), match.group(2)


def to_si(value, dimension=None):
    """SI float of a number or a "<number> <unit>" string; checks the unit's dimension
    against ``dimension`` (an SI unit such as "m", "rad", "s") when given."""
    if isinstance(value, bool):
        raise UnitError(f"expected a number or quantity, got {value!r}")
    if isinstance(value, (int, float)):
        number = float(value)
    elif isinstance(value, str):
        number, unit = split(value)
        if unit is not None and unit == dimension:
            pass                                   # the variable's own unit
        elif unit is not None:
            unit = spelled(unit)
            expected = f"; expected a quantity in {dimension} ({units_of(dimension)})" if dimension else ""
            if lookup(unit) is None:
                raise UnitError(f"unknown unit {unit!r} in {value!r}{expected or '; known: ' + ', '.join(UNITS)}"
                                " (and SI prefixes of those of factor 1)")
            factor, unit_dimension = lookup(unit)
            if dimension is not None and unit_dimension != dimension:
                raise UnitError(f"{value!r} is in {unit_dimension}{expected}")
            number *= factor
    else:
        raise UnitError(f"expected a number or a quantity string like '1 ms', got {value!r}")
    if not math.isfinite(number):
        raise UnitError(f"{value!r} is not a finite number")
    return number


# units of the metrics' numbers (scenarios.runs.metrics) that no parameter is written in
METRIC_UNITS = {"arcsec": (math.pi / 648000, "rad"), "mas": (math.pi / 648000000, "rad"), "%": (0.01, "1")}


def _factor(unit):
    """(SI factor, dimension) of a unit as written (UNITS, METRIC_UNITS); None if unknown."""
    unit = spelled(unit.strip())
    return UNITS.get(unit) or METRIC_UNITS.get(unit)


def in_unit(value, unit):
    """A "<number> <unit>" string in ``unit`` (a metric's: "µm", "kN", "arcsec", "%"):
    "0.5 mm" in "µm" is 500.0; a bare number is taken as in ``unit``. UnitError for an
    unknown unit or one of another dimension, naming the units that fit."""
    number, written = split(value) if isinstance(value, str) else (to_si(value), None)
    if written is None or spelled(written) == spelled(unit):
        return number
    given, target = _factor(written), _factor(unit)
    if given is None or target is None or given[1] != target[1]:
        fits = [u for u, (_, d) in {**UNITS, **METRIC_UNITS}.items() if target and d == target[1]] or [unit]
        said = "unknown unit" if given is None else "a unit of another dimension"
        raise UnitError(f"{value!r}: {said} {written!r}; expected a quantity in {unit} ({', '.join(fits)})")
    return number * given[0] / target[0]

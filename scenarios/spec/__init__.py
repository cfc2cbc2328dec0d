"""Scenario files: TOML, parsed and checked before anything runs.

A scenario names FMUs (by the kit's FMU names) with their parameters, the connections
between them, the time grid, the master algorithm, what to record, the metrics to report
and optionally one parameter to sweep. Every error points at the file, the key and the
problem. Quantities may carry units ("1 ms", "30 deg"); they are converted to SI here,
checked against the unit the FMU declares. The format: docs/scenarios.md and the
scenario-file reference generated from KEYS below (docs/generate.py).

A parameter written "@inst.var" takes the value of that output of another FMU at the
start time (e.g. the plant's initial pose from the telescope's reference pose).

Two stages: ``load`` checks the file's own structure (also: stop_time a whole number of
steps, metrics that count something); ``bind`` checks it against the FMUs' model
descriptions (variables exist, causalities, sizes and units of connections, every input
fed by exactly one source, values within the variables' declared min/max) and what the
models refuse that min/max cannot say (the telescope profile over the run). Both run
before the master starts.

The stages, in the order they run: ``keys`` (the table of keys and defaults, the Scenario),
``text`` (reading and its errors), ``parsing``, ``checks`` and ``binding``. The names the rest
of the kit uses are here.
"""
from scenarios.spec.binding import _value, as_data, bind, plain, sweep_value
from scenarios.spec.checks import check_links, check_models, check_rates, check_wiring, payload_problems
from scenarios.spec.keys import (
    _REQUIRED,
    FMI_VERSIONS,
    IMPLEMENTATIONS,
    KEYS,
    MAX_FILE_BYTES,
    METRIC_KINDS,
    TOP_KEYS,
    Link,
    Metric,
    Requirement,
    Scenario,
    enumeration,
    expand,
    judge,
    unmet,
)
from scenarios.spec.parsing import load, parse, parse_data, sources_of, with_sources
from scenarios.spec.text import (
    Problems,
    ScenarioError,
    check_name,
    file_label,
    read_text,
    read_toml,
    run_label,
    shown,
    unknown_keys,
)

__all__ = ['FMI_VERSIONS', 'IMPLEMENTATIONS', 'KEYS', 'Link', 'MAX_FILE_BYTES', 'METRIC_KINDS', 'Metric', 'Problems',
           'Requirement', 'Scenario', 'ScenarioError', 'TOP_KEYS', '_REQUIRED', '_value', 'as_data', 'bind',
           'check_links', 'check_models', 'check_name', 'check_rates', 'check_wiring', 'enumeration', 'expand',
           'file_label', 'judge', 'load', 'parse', 'parse_data', 'payload_problems', 'plain', 'read_text', 'read_toml',
           'run_label', 'shown', 'sources_of', 'sweep_value', 'unknown_keys', 'unmet', 'with_sources']

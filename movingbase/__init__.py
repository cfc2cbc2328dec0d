"""movingbase: co-simulation kit for parallel mechanisms on moving bases.

One import name over the repository's folders, one job each (the data flows one way):

- ``movingbase.plant``: rigid-body models (6-UPS hexapod, 3T mechanism, telescope base), C kernel;
- ``movingbase.controller``: PID leg control with model feedforward, its design;
- ``movingbase.fmu_src``: the FMUs (pythonfmu and native C, FMI 2.0);
- ``movingbase.scenarios``: scenario files, the co-simulation master, results and reports.

Command line: ``movingbase run telescope_slew`` (or ``python -m movingbase run ...``).
"""
__version__ = "0.2.0"

"""movingbase: co-simulation kit for parallel mechanisms on moving bases.

One import name over the repository's folders, one job each (the data flows one way):

- ``movingbase.plant``: rigid-body models (6-UPS hexapod, 3T mechanism, telescope base), C kernel;
- ``movingbase.controller``: PID leg control with model feedforward, its design;
- ``movingbase.fmu_src``: the FMUs (pythonfmu and native C, FMI 2.0);
- ``movingbase.scenarios``: scenario files, the co-simulation master, results and reports.

Command line: ``movingbase run telescope_slew`` (or ``python -m movingbase run ...``).
In Python (notebooks): ``movingbase.run("telescope_slew", ci=True)`` returns a Result
(time series as numpy arrays or pandas, metrics, flags, charts); ``movingbase.campaign``
the same for campaign files (scenarios/api.py).
"""
from typing import TYPE_CHECKING, Any

__version__ = "0.2.0"
__all__ = ["run", "campaign", "load_scenario", "Result", "RunResult", "CampaignResult", "__version__"]

if TYPE_CHECKING:
    from .scenarios.api import CampaignResult, Result, RunResult, campaign, load_scenario, run


def __getattr__(name: str) -> Any:
    """The API on first use: ``movingbase --version`` and the command line do not pay
    for importing matplotlib and the master (PEP 562)."""
    if name in __all__:
        from .scenarios import api
        return getattr(api, name)
    raise AttributeError(f"module 'movingbase' has no attribute {name!r}")

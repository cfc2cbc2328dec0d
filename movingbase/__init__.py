"""movingbase: co-simulation kit for parallel mechanisms on moving bases.

One import name over the repository's folders, one job each (the data flows one way):

- ``plant``: rigid-body models (6-UPS hexapod, 3T mechanism, telescope base), C kernel;
- ``controller``: PID leg control with model feedforward, its design;
- ``fmu_src``: the FMUs (pythonfmu FMI 2.0, native C FMI 2.0 and 3.0);
- ``scenarios``: scenario files, the co-simulation master, results and reports.

Command line: ``movingbase run telescope_slew`` (or ``python -m movingbase run ...``).
In Python (notebooks): ``movingbase.run("telescope_slew", ci=True)`` returns a Result
(time series as numpy arrays or pandas, metrics, flags, charts); ``movingbase.campaign``
the same for campaign files; ``movingbase.budget`` a geometric tolerance budget;
``movingbase.regress`` holds scenario files against stored baselines (CI);
``movingbase.fmus()`` the FMU files for other FMI tools, ``movingbase.export_ssp`` a scenario
as an SSP file and ``movingbase.simulate_ssp`` its run in fmpy (movingbase/api.py).
"""
import typing as _typing

__version__ = "0.2.0"
__all__ = ["run", "campaign", "budget", "regress", "load_scenario", "fmus", "export_ssp", "simulate_ssp",
           "loop_analysis", "Result", "RunResult", "CampaignResult", "BudgetResult", "Charts", "LoopAnalysis",
           "RunWarning", "ScenarioError", "__version__"]

if _typing.TYPE_CHECKING:
    from movingbase.api import (
        BudgetResult,
        CampaignResult,
        Charts,
        LoopAnalysis,
        Result,
        RunResult,
        RunWarning,
        budget,
        campaign,
        export_ssp,
        fmus,
        load_scenario,
        loop_analysis,
        regress,
        run,
        simulate_ssp,
    )
    from scenarios.spec import ScenarioError


def __dir__() -> list[str]:
    """The API for tab completion (``movingbase.ru<TAB>``), not the module's helpers."""
    return sorted(__all__)


def __getattr__(name: str) -> _typing.Any:
    """The API on first use: ``movingbase --version`` and the command line do not pay
    for importing matplotlib and the master (PEP 562)."""
    if name == "ScenarioError":
        from scenarios.spec import ScenarioError
        return ScenarioError
    if name in __all__:
        from movingbase import api
        return getattr(api, name)
    raise AttributeError(f"module 'movingbase' has no attribute {name!r}")

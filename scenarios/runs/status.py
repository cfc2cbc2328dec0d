"""The one status vocabulary of a run, said the same by ``movingbase.run``, campaigns and
budgets: in reprs, tables, progress bars, summary files and the command's exit status.
A user who keeps ``status == "ok"`` keeps results only (a flagged run once read "ok" in a
campaign's table: only its flags column told).

- ``ok``: ran to its stop time and nothing was seen wrong: its numbers are results;
- ``flagged``: ran to its stop time, but something was seen wrong (scenarios.runs.flags):
  its numbers are not results;
- ``failed``: an FMU stopped it before its stop time (what it recorded up to then is kept);
- ``refused``: the checks refused it before it ran (a ScenarioError says why);
- ``not run``: not run (yet): an interrupted campaign's remaining runs.
"""
OK, FLAGGED, FAILED, REFUSED, NOT_RUN = "ok", "flagged", "failed", "refused", "not run"
STATUSES = (OK, FLAGGED, FAILED, REFUSED, NOT_RUN)   # in the order counts are told

# the command's exit status of a set of runs: the worst one's (0 only if every run is a
# result; 2 is argparse's, a mistyped command line)
EXIT = {OK: 0, FLAGGED: 3, FAILED: 1, REFUSED: 1, NOT_RUN: 1}
_WORST = (FAILED, REFUSED, NOT_RUN, FLAGGED, OK)


def of_run(failure, flags):
    """The status of a run that ran: ``failure`` (why an FMU stopped it; None or '' if
    none) and its ``flags``."""
    return FAILED if failure else FLAGGED if flags else OK


def of_record(record):
    """The status of a campaign run from its stored result (scenarios.runs.engine: status
    "ok" or "failed" as the store keeps it, and its flags), None meaning not on disk."""
    if record is None:
        return NOT_RUN
    return of_run(record.get("status") != OK and (record.get("error") or FAILED), record.get("flags"))


def counts(statuses):
    """{status: how many} in the vocabulary's order, those that occur only."""
    statuses = list(statuses)
    unknown = set(statuses) - set(STATUSES)
    if unknown:
        raise ValueError(f"unknown run status {sorted(unknown)}; the statuses are {', '.join(STATUSES)}")
    return {s: statuses.count(s) for s in STATUSES if s in statuses}


def told(statuses, noun="run"):
    """"10 runs: 7 ok, 3 flagged"."""
    found = counts(statuses)
    total = sum(found.values())
    return f"{total} {noun}{'s' * (total != 1)}: " + ", ".join(f"{n} {s}" for s, n in found.items())


def worst(statuses):
    """The worst status among ``statuses`` (ok if none)."""
    found = set(statuses)
    return next((s for s in _WORST if s in found), OK)


def exit_status(statuses):
    """The command's exit status for runs of these statuses: EXIT of the worst one."""
    return EXIT[worst(statuses)]

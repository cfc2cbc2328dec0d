"""studies/tolerance_budget.py: the committed page is what its stored results write (the page
cannot drift from docs/tolerance_budget.json), and the stored numbers keep the issue's goals."""
import json

import pytest

from studies import tolerance_budget as study


def test_the_page_is_written_from_the_stored_results():
    store = json.loads(study.STORE.read_text())
    assert study.REPORT.read_text() == study.report(store)


def test_the_stored_budget_meets_the_goals():
    """Sobol intervals narrower than 0.05 for every group, the allocations checked at 99.7 %."""
    store = json.loads(study.STORE.read_text())
    for name in study.BUDGETS:
        sobol = store[name]["sobol"]
        assert 2 * max(map(max, sobol["total_conf"] + sobol["first_conf"])) < 0.05
        allocation = store[name]["allocation"]
        assert allocation["verified"] and all(c["high"] < c["target"] for c in allocation["check"].values())
        assert store[name]["samples"] == 1_000_000


def test_a_damaged_store_is_told_not_a_json_traceback(tmp_path):
    truncated = tmp_path / "tolerance_budget.json"
    truncated.write_text(study.STORE.read_text()[:5000])
    with pytest.raises(SystemExit, match=r"tolerance_budget.json: not whole JSON \(.* at line \d+, column \d+: "
                                         r"truncated or damaged\); run python -m studies.tolerance_budget"):
        study.read_store(truncated)
    truncated.write_text('{"default": {}}')
    with pytest.raises(SystemExit, match="holds no results of default, nanshan"):
        study.read_store(truncated)
    with pytest.raises(SystemExit, match="cannot read it"):
        study.read_store(tmp_path / "missing.json")

"""Scenario files edited as a user would, and the refusal they must get (spec and hostile-input tests)."""
import pytest

from scenarios import spec
from scenarios.runs import runner

SLEW = runner.resolve("telescope_slew").read_text()


def edited(text, *changes):
    """text with each (old, new) replaced once; every old must be there (no silent no-op)."""
    for old, new in changes:
        assert old in text, old
        text = text.replace(old, new, 1)
    return text


def refused(text, key, *parts, descriptions=None, overrides=None):
    """The ScenarioError message of parsing (and binding, with descriptions) text; asserts
    it starts with file and key and contains every part."""
    with pytest.raises(spec.ScenarioError) as error:
        scenario = spec.parse(text, "bad.toml", overrides)
        spec.bind(scenario, descriptions)
    message = str(error.value)
    assert message.startswith(f"bad.toml: {key}: "), message
    for part in parts:
        assert part in message, (part, message)
    return message


def interrupt_the_second_run(monkeypatch):
    """Ctrl-C as it lands during the second run of a sweep: scenarios.runs.single.run raises
    KeyboardInterrupt on its second call (a timed key press would race 0.1 s runs);
    monkeypatch.undo() puts the real one back."""
    from scenarios.runs import single
    real, calls = single.run, []

    def interrupted_at_the_second(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*args, **kwargs)
    monkeypatch.setattr(single, "run", interrupted_at_the_second)

"""Write tests/golden/<scenario>.json: the [ci] run's metrics with tolerances.

Each tolerance is twice the change of the metric when the plant integrator's max_step is
halved, i.e. the size of the integrator's own error in that number, floored at 1e-9 of
the value and at FLOOR (µm, µrad, kN: about 15 ulp of a 3 m leg length in µm, so that
reordering a floating-point sum is not a regression): a change beyond it is a change of
behaviour, not of rounding.

    python -m tests.update_golden [names]
"""
import json
import pathlib
import re
import sys
import tempfile

from scenarios.runs import runner

GOLDEN = pathlib.Path(__file__).parent / "golden"
FLOOR = 1e-8


def _metrics(name, out, max_step=None):
    scenario, paths, descriptions, values = runner.prepare(runner.resolve(name), ci=True)
    text = runner.resolve(name).read_text()
    if max_step:   # every plant's max_step times max_step
        text, n = re.subn(r'max_step = "([0-9.]+) ms"', lambda m: f'max_step = "{float(m[1]) * max_step:g} ms"', text)
        assert n
    path = pathlib.Path(out) / f"{name}.toml"
    path.write_text(text)
    return {r.label: r.metrics for r in runner.run_scenario(path, out, ci=True, progress=False)[1]}


def main(names):
    GOLDEN.mkdir(exist_ok=True)
    for name in names:
        with tempfile.TemporaryDirectory() as tmp:
            base = _metrics(name, tmp)
            fine = _metrics(name, tmp, max_step=0.5)
        golden = {label: {metric: {key: (value, 2 * max(abs(value - fine[label][metric][key]), 1e-9 * abs(value),
                                                         FLOOR))
                                   for key, value in values.items() if key != "unit"}
                          for metric, values in run.items()} for label, run in base.items()}
        (GOLDEN / f"{name}.json").write_text(json.dumps(golden, indent=1))
        print(f"wrote {GOLDEN / name}.json")


if __name__ == "__main__":
    main(sys.argv[1:] or sorted(p.stem for p in runner.SHIPPED.glob("*.toml")))

"""studies/wind_feedforward.py: every case is a scenario the checker takes, the oracle reads
the drag's own speed, the coherence bandwidth is where Davenport's gamma^2 is 1/2, and in
co-simulation the feedforward fed the drag's own speed takes the wind's error out (the
chain Wind -> controller -> legs -> plant holds the drag the plant takes)."""
import math
import tomllib

import numpy as np
import pytest

from scenarios import spec
from scenarios.runs import runner
from studies import wind_feedforward as study


@pytest.mark.parametrize("name", list(study.CASES))
def test_every_case_is_a_valid_scenario(name):
    text = study.case_text(name)
    spec.parse(text, f"{name}.toml")
    data = tomllib.loads(text)
    sources = {c["from"] for c in data["connections"] if c["to"] == "controller.wind_speed"}
    assert sources == {"wind.drag_speed" if name == study.ORACLE else "wind.anemometer_speed"}
    gain, across, upstream, lag, cutoff = study.CASES[name]
    assert data["sweep"]["values"] == [gain]
    assert data["fmus"]["wind"]["parameters"]["anemometer_time_constant"] == lag


def test_coherence_bandwidth_is_where_gamma_squared_is_one_half():
    f = study.coherence_bandwidth(3.0, 4.0, speed=12.0, decay=9.0)
    assert math.exp(-9.0 * f * 5.0 / 12.0) ** 2 == pytest.approx(0.5)
    assert study.coherence_bandwidth(0.0, 0.0) == math.inf


@pytest.mark.slow   # three [ci] runs, ~5 s
def test_the_drag_speed_feedforward_takes_the_wind_out(tmp_path):
    """[ci] runs: without feedforward the wind adds to the calm loop's error; fed the drag's
    own speed, the feedforward brings the error back near calm air's."""
    peaks = {}
    for name, over in (("off", None), (study.ORACLE, None), ("calm", {"mean_speed": 0.0})):
        text = study.case_text("off" if name == "calm" else name)
        if over:
            text = text.replace('mean_speed = "10 m/s"', 'mean_speed = "0 m/s"')
        path = tmp_path / f"{study._slug(name)}.toml"
        path.write_text(text)
        _, (run,), _ = runner.run_scenario(path, tmp_path / "out", ci=True, progress=False, charts="none")
        assert run.flags == []
        peaks[name] = run.metrics["pose error"]["peak"]
    assert peaks["off"] > 1.5 * peaks["calm"]
    assert np.isclose(peaks[study.ORACLE], peaks["calm"], rtol=0.05), peaks

"""The recording in C (scenarios/cosim/c/cosim.c reads the recorded values at each record point
into a block of rows; master.Recorder hands whole blocks to the records, the metrics and
the watch) against independent truths: reading is free of side effects, so a run
recorded every step holds, bit for bit, the rows of the same run recorded every tenth
step; a metric recomputed offline with numpy from the recorded columns; blocks handed
over in any sizes against rows fed one at a time; a recorded value whose read fails
mid-run (FMI 2.0 and FMI 3.0) stops the run as a failed step does, the rows before it
those of the run that did not fail."""
import ctypes
import dataclasses
import math

import numpy as np
import pytest

from scenarios import spec
from scenarios.cosim import master
from scenarios.cosim.fmi import Instance, Instance3
from scenarios.runs import flags, metrics, runner, single

STROKE = (np.full(6, -0.15), np.full(6, 0.15))   # a Watched loop's ends: +-150 mm


def prepared(fmi_version=None, feedforward="moving_base"):
    """paper_manoeuvre [ci] (4 s at 1 ms, recorded every 10 ms, metrics from 2 s), native FMUs."""
    scenario, paths, descriptions, values = runner.prepare(runner.resolve("paper_manoeuvre"), ci=True,
                                                           fmi_version=fmi_version)
    inst, var, value = spec.sweep_value(scenario, descriptions, feedforward)
    values[inst][var] = value
    return scenario, paths, values


def run(scenario, paths, values, progress=None):
    return single.run(scenario, paths, values, None, "run", [metrics.make(m) for m in scenario.metrics], progress)


def counting_calls(monkeypatch):
    """Count master.Loop.steps calls (the C calls that step and record)."""
    calls, real = [], master.Loop.steps

    def counted(self, k, count):
        calls.append(count)
        return real(self, k, count)
    monkeypatch.setattr(master.Loop, "steps", counted)
    return calls


def test_a_row_each_step_holds_the_rows_of_a_row_each_tenth_step(monkeypatch):
    """Every step recorded (4001 rows, more per C call than the block holds, so the calls
    end where the block fills) against every tenth step (as shipped): every tenth row is
    the other run's row bit for bit, times included; each run makes only the C calls its
    CHUNK and block sizes need, not one per row."""
    scenario, paths, values = prepared()
    every_step = dataclasses.replace(scenario, record_interval=scenario.step)
    steps = round((scenario.stop_time - scenario.start_time) / scenario.step)
    calls = counting_calls(monkeypatch)
    tenth = run(scenario, paths, values)
    assert len(calls) == math.ceil(steps / single.CHUNK)
    calls.clear()
    each = run(every_step, paths, values)
    assert len(calls) == math.ceil(steps / master.Recorder.ROWS)
    assert tenth.records.count == steps // 10 + 1 and each.records.count == steps + 1
    assert each.records.names == tenth.records.names
    assert each.records.time[::10].tobytes() == tenth.records.time.tobytes()
    assert each.records.values[::10].tobytes() == tenth.records.values.tobytes()


def test_a_metric_is_what_numpy_makes_of_the_recorded_column():
    """The peak metric of the leg forces (from 2 s) against the RMS and peak numpy
    computes from the recorded column over the rows at or after 2 s."""
    scenario, paths, values = prepared()
    done = run(scenario, paths, values)
    (peak,) = [m for m in scenario.metrics if m.kind == "peak"]
    forces = np.column_stack([done.records[f"controller.leg_force[{i}]"] for i in range(1, 7)])
    kept = forces[done.records.time >= peak.start - 1e-12]
    assert 0 < len(kept) < len(forces)
    result = done.metrics[peak.name]
    assert result["peak"] == np.abs(kept).max() * 1e-3
    assert result["rms"] == pytest.approx(np.sqrt(np.mean(kept ** 2)) * 1e-3, rel=1e-12)


def test_a_small_block_changes_nothing_and_progress_still_moves(monkeypatch):
    """A block of 7 rows (a C call ends every 70 steps) against the default one, both with
    progress: the same records, metrics, series and flags bit for bit, and the progress
    callback called at the same ~200 points."""
    scenario, paths, values = prepared(feedforward="fixed_base")
    outcomes = []
    for rows in (master.Recorder.ROWS, 7):
        monkeypatch.setattr(master.Recorder, "ROWS", rows)
        seen = []
        done = run(scenario, paths, values, seen.append)
        outcomes.append((done.records.time.tobytes(), done.records.values.tobytes(), repr(done.metrics),
                         {k: (t.tobytes(), v.tobytes()) for k, (t, v) in done.series.items()}, repr(done.flags), seen))
    assert outcomes[0] == outcomes[1]
    assert 190 <= len(outcomes[0][-1]) <= 210


def fed_in_pieces(feed, t, rows, sizes):
    """Feed rows in consecutive pieces of the given sizes (cycled)."""
    k, i = 0, 0
    while k < len(t):
        n = sizes[i % len(sizes)]
        feed(t[k:k + n], rows[k:k + n])
        k, i = k + n, i + 1


@pytest.mark.parametrize("sizes", [[1], [3, 300, 1, 255, 256, 257], [700]])
def test_blocks_of_any_size_equal_rows_one_at_a_time(sizes, monkeypatch):
    """A metric and the watch fed 700 random rows in pieces of the given sizes against
    the same rows fed one at a time through the per-row call (metric.update; the watch a
    row each): the blocks flush at the same row counts, so every number is bit for bit
    the same (series thinned across blocks with MAX_POINTS 40)."""
    monkeypatch.setattr(metrics, "MAX_POINTS", 40)
    rng = np.random.default_rng(21)
    t = np.arange(700) * 1e-2
    rows = rng.standard_normal((700, 12)) * 1e3
    rows[400, 3] = np.nan
    one, pieces = metrics.Peak("f", "c.f"), metrics.Peak("f", "c.f")
    for k in range(len(t)):
        one.update(t[k], {"c.f": rows[k, :6]})
    fed_in_pieces(lambda tt, rr: pieces.feed(tt, [rr[:, :6]]), t, rows, sizes)
    assert repr(one.result()) == repr(pieces.result())
    assert [a.tobytes() for a in one.series()] == [a.tobytes() for a in pieces.series()]

    def watch():
        w = flags.Watch([flags.Watched("c", "f", "l", (("c.force_limit", 2e3),), STROKE)], window=0.5)
        w.bind({"f": slice(0, 6), "l": slice(6, 12)})
        return w
    single, many = watch(), watch()
    fed_in_pieces(single.feed, t, rows, [1])
    fed_in_pieces(many.feed, t, rows, sizes)
    assert single.flags() == many.flags() and single.flags()
    assert single.rows == many.rows == len(t) and all(
        single.held[k].tobytes() == many.held[k].tobytes() for k in single.held)
    assert all(single.env[r].tobytes() == many.env[r].tobytes() for r in ("f", "l"))


def failing_reads(monkeypatch, inst, variable, call):
    """Make instance ``inst``'s reads of the values holding ``variable`` (only the recorder
    reads them: it is recorded, not connected) answer Error from their ``call``-th on, for
    every Instance (FMI 2.0 fmi2GetReal) and Instance3 (fmi3GetFloat64) made from now on."""
    kinds = {Instance: ("fmi2GetReal", []), Instance3: ("fmi3GetFloat64", [ctypes.c_size_t])}
    for cls, (function, extra) in kinds.items():
        real_raw = cls.raw
        kind = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.POINTER(ctypes.c_uint), ctypes.c_size_t,
                                ctypes.POINTER(ctypes.c_double), *extra)

        def raw(self, name, real_raw=real_raw, function=function, kind=kind):
            fn = real_raw(self, name)
            if self.name != inst or name != function:
                return fn
            if not hasattr(self, "_failing"):
                target = self.vr(variable)
                target = self.arrays[target][0] if isinstance(self, Instance3) else target
                count = [0]

                def wrapped(component, vr, n, *rest):
                    if target in vr[:n]:
                        count[0] += 1
                        if count[0] >= call:
                            return 3   # fmi2Error / fmi3Error
                    return fn(component, vr, n, *rest)
                self._failing = kind(wrapped)    # kept alive with the instance
            return self._failing
        monkeypatch.setattr(cls, "raw", raw)


@pytest.mark.parametrize("fmi_version", [None, 3])
@pytest.mark.parametrize("call", [1, 301])
def test_a_failing_read_of_a_recorded_value_stops_the_run_with_the_rows_before_it(fmi_version, call, monkeypatch):
    """plant.pose (recorded, not connected) read with Error at its call-th read (1: the
    row at the start time): RunFailed naming the instance, getReal and the time of the
    last step, the run's steps up to that row, its rows those of the same run without the
    failure, its metrics those of its rows, flagged cut_short."""
    scenario, paths, values = prepared(fmi_version)
    whole = run(scenario, paths, values)
    failing_reads(monkeypatch, "plant", "pose[1]", call)
    with pytest.raises(master.RunFailed) as failed:
        run(scenario, paths, values)
    every = round(scenario.record_interval / scenario.step)
    steps = (call - 1) * every
    last = scenario.start_time + max(0, steps - 1) * scenario.step
    message = f"FMU instance 'plant' failed in getReal at t = {last:.6g} s (status ERROR)"
    assert str(failed.value).startswith(message)
    stopped = failed.value.run
    assert stopped.failure.startswith(message.rsplit(" (", 1)[0]) and stopped.steps == steps
    assert stopped.records.count == call - 1
    assert stopped.records.values.tobytes() == whole.records.values[:call - 1].tobytes()
    assert stopped.records.time.tobytes() == whole.records.time[:call - 1].tobytes()
    assert "cut_short" in {f.kind for f in stopped.flags}
    peak = next(m for m in scenario.metrics if m.kind == "peak")
    forces = np.column_stack([stopped.records[f"controller.leg_force[{i}]"] for i in range(1, 7)])
    kept = forces[stopped.records.time >= peak.start - 1e-12]
    if len(kept):
        assert stopped.metrics[peak.name]["peak"] == np.abs(kept).max() * 1e-3
    else:
        assert math.isnan(stopped.metrics[peak.name]["peak"])


def test_a_peak_between_recorded_rows_is_still_counted():
    """Records kept every 50 ms, the metrics read every step (record.metric_interval 1 ms):
    the records are every 50th row of the run recorded every step, bit for bit, and every
    metric is that run's, bit for bit. The pose error's peak (0.2132 µm), numpy's largest
    distance between the every-step run's recorded pose and reference, lies between two
    recorded rows: the kept rows' largest is 0.2088 µm, which is all the metrics fed the
    recorded rows only (no metric_interval) see."""
    scenario, paths, values = prepared()
    each = run(dataclasses.replace(scenario, record_interval=scenario.step), paths, values)
    kept = run(dataclasses.replace(scenario, record_interval=0.05, metric_interval=scenario.step), paths, values)
    only_kept = run(dataclasses.replace(scenario, record_interval=0.05), paths, values)
    assert kept.records.count == (each.records.count - 1) // 50 + 1 == 81
    assert kept.records.time.tobytes() == each.records.time[::50].tobytes()
    assert kept.records.values.tobytes() == each.records.values[::50].tobytes()
    assert kept.metrics == each.metrics
    (pose,) = [m for m in scenario.metrics if m.kind == "pose_tracking"]

    def distance(r):   # [µm], the rows the metric counts
        d = np.column_stack([r.records[f"plant.pose[{i}]"] - r.records[f"base.reference_pose[{i}]"]
                             for i in (1, 2, 3)])
        return np.linalg.norm(d[r.records.time >= pose.start - 1e-12], axis=1) * 1e6
    truth = distance(each).max()
    assert kept.metrics[pose.name]["peak"] == pytest.approx(truth, rel=1e-12) == pytest.approx(0.2132, abs=1e-4)
    assert distance(kept).max() == pytest.approx(0.2088, abs=1e-4)            # between the recorded rows
    assert only_kept.metrics[pose.name]["peak"] == pytest.approx(distance(kept).max(), rel=1e-12)


@pytest.mark.parametrize("metric_interval", ["3 ms", "0.5 ms", "20 ms"])
def test_a_metric_interval_off_the_grid_is_refused(metric_interval, tmp_path):
    """record.metric_interval must be a whole multiple of step dividing record.interval (10 ms)."""
    text = runner.resolve("paper_manoeuvre").read_text().replace(
        '[record]\n', f'[record]\nmetric_interval = "{metric_interval}"\n', 1)
    path = tmp_path / "scene.toml"
    path.write_text(text)
    with pytest.raises(spec.ScenarioError, match="record.metric_interval.*whole multiple of step"):
        spec.load(path)


def test_records_written_later_are_the_records_written_now_and_settle_says_a_failure(tmp_path, monkeypatch):
    """Records.save(later=True), as a scene's runs write theirs while the next one steps:
    once atomic.settle() returns, the same bytes as a save now; a write that fails is raised
    by settle (the caller's thread) and leaves no file and no part behind."""
    import time

    from fmu_src import atomic
    from scenarios.cosim.records import Records, read_records
    rng = np.random.default_rng(3)
    records = Records.of(np.arange(500) * 1e-3, ["a.x", "b.y [1]"], ["m", "N"], rng.normal(size=(500, 2)))
    records.save(tmp_path / "now.npz")
    assert records.save(tmp_path / "later", later=True) == tmp_path / "later.npz"
    atomic.settle()
    assert (tmp_path / "later.npz").read_bytes() == (tmp_path / "now.npz").read_bytes()
    assert read_records(tmp_path / "later.npz").values.tobytes() == records.values.tobytes()
    records.save(tmp_path / "gone" / "x.npz", later=True)          # its folder does not exist
    with pytest.raises(FileNotFoundError):
        atomic.settle()
    assert not (tmp_path / "gone").exists() and atomic._LATER == []
    calls = []
    def write(path, data):
        time.sleep(0.05 if data == b"1" else 0.0)                     # the first write is the slower
        calls.append(data)
    monkeypatch.setattr(atomic, "write_bytes", write)
    for value in (b"1", b"2"):                                       # the same path twice: in order
        atomic.write_bytes_later(tmp_path / "twice", value)
    atomic.settle()
    assert calls == [b"1", b"2"]

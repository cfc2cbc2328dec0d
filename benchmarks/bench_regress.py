"""What `movingbase regress` costs against `movingbase run`, side by side in one run: each
shipped scene at its [ci] length, run as the command runs it (scenarios.runs.runner.
run_scenario: records, metrics.json, charts and report written; and without charts) and compared with its
baseline (scenarios.runs.regress, the baseline made first, not timed), alternately,
``--repeat`` times each; the least of each is kept (the machine is shared: the least is the
one other work slowed the least); a requirement of the file not met at [ci] length is
no failure of the comparison. CPU time of this process is printed beside the wall
time, as other work does not inflate it. The goal: regress at most 1.2x run. The
baselines' --update (a second run at half the plant's step) is timed once per scene too.

    python -m benchmarks.bench_regress [--scenes telescope_slew paper_manoeuvre] [--repeat 2]
"""
import argparse
import pathlib
import tempfile
import time

from scenarios.runs import regress, runner


def _timed(call):
    wall, cpu = time.perf_counter(), time.process_time()
    call()
    return time.perf_counter() - wall, time.process_time() - cpu


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="*", default=runner.shipped_names(), help="shipped scenes (default: all)")
    parser.add_argument("--repeat", type=int, default=2, help="times each is timed (the least is kept)")
    args = parser.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        baseline, out = pathlib.Path(tmp) / "baseline", pathlib.Path(tmp) / "out"
        for name in args.scenes:
            runner.run_scenario(name, out, ci=True, progress=False)   # FMUs built and loaded once, untimed
            update = _timed(lambda: regress.regress_scene(name, baseline, update=True, ci=True))
            run, bare, held = [], [], []
            for _ in range(args.repeat):
                run.append(_timed(lambda: runner.run_scenario(name, out, ci=True, progress=False)))
                bare.append(_timed(lambda: runner.run_scenario(name, out / "bare", ci=True, progress=False,
                                                               charts="none")))
                outcome = []
                held.append(_timed(lambda: outcome.append(regress.regress_scene(name, baseline, ci=True))))
                told = [f.kind for r in outcome[0].runs for f in r.findings]
                assert not outcome[0].error and set(told) <= {"requirement"}, (name, outcome[0].error, told)
            rows.append((name, min(run), min(bare), min(held), update))
    print("CPU seconds of this process (wall in brackets); ratios of CPU")
    print(f"{'scene [ci]':32s} {'run':>16s} {'run, no charts':>16s} {'regress':>16s} {'/ run':>6s} {'/ bare':>6s} "
          f"{'update':>16s}")

    def cell(t):
        return f"{t[1]:6.2f} ({t[0]:6.2f})"
    for name, run, bare, held, update in rows:
        print(f"{name:32s} {cell(run):>16s} {cell(bare):>16s} {cell(held):>16s} {held[1] / run[1]:5.2f}x "
              f"{held[1] / bare[1]:5.2f}x {cell(update):>16s}")
    total = [tuple(sum(r[k][j] for r in rows) for j in (0, 1)) for k in (1, 2, 3, 4)]
    print(f"{'all':32s} {cell(total[0]):>16s} {cell(total[1]):>16s} {cell(total[2]):>16s} "
          f"{total[2][1] / total[0][1]:5.2f}x {total[2][1] / total[1][1]:5.2f}x {cell(total[3]):>16s}")
    print("goal: regress <= 1.2x run")


if __name__ == "__main__":
    main()

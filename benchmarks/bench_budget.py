"""What a sample of the dynamic budget (scenarios/campaigns/dynamic_budget.toml, issue 41)
costs, before and after the guard's cost was cut, side by side in one run, in CPU seconds
(the machine is shared: wall time measures the other engineers' load as much as the code).

* the check before the runs (scenarios.runs.campaign.CampaignJobs.check, serial in the
  client): before, each sample's loop built by python-control (controller.design.mode_loop,
  ~30 closed loops per step-limit search) and predicted anew (the prediction's cache was
  keyed by every plant and sensor parameter, which each sample draws); now the loop's state
  space in numpy, and the motion and the step limit cached by what they read;
* a run (scenarios.runs.engine.execute, the workers' own call): its detectors' window is
  taken from the loop's step limit and least-damped pole (flags.Watch.for_scenario), which
  each run computes; the stepping itself is unchanged.

From the CPU per sample it projects the whole campaign on 2 idle cores (the check serial,
the runs on 2 workers) and prints the kit's own estimate beside it.

    python benchmarks/bench_budget.py [--samples 4] [--runs 2]
"""
import argparse
import contextlib
import dataclasses
import statistics
import time

from controller import design
from scenarios.runs import campaign as campaigns
from scenarios.runs import engine

CAMPAIGN = "dynamic_budget"


def _python_control_poles(mass, gains, comm_step, loop):
    """The guard's poles as it took them before: python-control's feedback of mode_loop."""
    import control
    return control.feedback(design.mode_loop(mass, gains, comm_step, loop)).poles()


@contextlib.contextmanager
def python_control_guard():
    """The observer loop's poles from python-control (the guard before issue 41's goal 4)."""
    fast = design._poles
    design._poles = lambda mass, gains, h, loop: (_python_control_poles(mass, gains, h, loop)
                                                  if loop.observer_bandwidth > 0 else fast(mass, gains, h, loop))
    try:
        yield
    finally:
        design._poles = fast


def check_cpu(made, cases, before):
    """CPU seconds of the check per sample: ``before``, each sample checked with a cache of its
    own and python-control's loops (as every sample was: its key missed); else all at once."""
    campaign = made.campaign
    began = time.process_time()
    try:
        if before:
            with python_control_guard():
                for case in cases:
                    made.campaign = dataclasses.replace(campaign, cases=[case])
                    made.check()
        else:
            made.campaign = dataclasses.replace(campaign, cases=cases)
            made.check()
    finally:
        made.campaign = campaign
    return (time.process_time() - began) / len(cases)


def run_cpu(job, blobs, before):
    """CPU seconds of one run as a worker runs it, and its metrics."""
    with python_control_guard() if before else contextlib.nullcontext():
        began = time.process_time()
        result = engine.execute(job, blobs)
        cpu = time.process_time() - began
    assert result["status"] == "ok", result.get("error")
    return cpu, result["metrics"]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=4, help="samples whose check is timed before")
    parser.add_argument("--runs", type=int, default=2, help="samples run, each before and after (interleaved)")
    args = parser.parse_args(argv)
    campaign = campaigns.load(CAMPAIGN)
    made = campaigns.CampaignJobs(campaign)
    cases = campaign.cases[:args.samples]
    check_cpu(made, cases[:1], False)          # imports and first calls, not counted
    # interleaved twice (the mean of each), so load hits both alike; now: every sample, as the
    # campaign checks them (the first pays for the motion and the step limit the others reuse)
    before, after = [], []
    for _ in range(2):
        after.append(check_cpu(made, campaign.cases, False))
        before.append(check_cpu(made, cases, True))
    before, after = statistics.mean(before), statistics.mean(after)
    estimate = made.cost()
    made.campaign = dataclasses.replace(campaign, cases=campaign.cases[:args.runs])
    made.check()
    jobs = list(made)
    made.campaign = campaign
    blobs = {digest: open(path, "rb").read() for digest, path in made.files.items()}
    runs = {True: [], False: []}
    for job in jobs:
        for old in (False, True):
            cpu, found = run_cpu(job, blobs, old)
            runs[old].append((cpu, found))
    assert all(a[1] == b[1] for a, b in zip(runs[True], runs[False])), "the metrics differ before and after"
    run_before, run_after = (statistics.median(c for c, _ in runs[old]) for old in (True, False))
    n = campaign.sample.samples
    print(f"check per sample: before {before:.3f} s CPU ({len(cases)} samples), now {after * 1e3:.1f} ms "
          f"(all {len(campaign.cases)}; {before / after:.0f}x less)")
    print(f"run per sample ({len(jobs)} samples, metrics equal): before {run_before:.2f} s CPU, now "
          f"{run_after:.2f} s ({run_before / run_after:.2f}x less)")
    for label, check, run in (("before", before, run_before), ("now", after, run_after)):
        total = n * (check + run)
        wall = n * check + n * run / 2
        print(f"{label}: {n} samples, {total:.0f} s CPU; on 2 idle cores ~{wall / 60:.1f} min (check "
              f"{n * check:.0f} s serial, then the runs on 2 workers)")
    print(f"the kit's estimate before a run (scenarios.runs.estimates, from the step count): {estimate.text()}")


if __name__ == "__main__":
    main()

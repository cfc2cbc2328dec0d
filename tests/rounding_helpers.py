"""Tolerances that rounding explains, for comparisons with numbers stored by another machine.

A value computed here and the same value stored by another processor, numpy build, libm or
compiler differ by rounding alone: each intermediate result may round one way here and the
other way there, and the function carries that difference to its output as it carries a change
of its inputs. So the difference a stored value may show is measured here, in this run: the
largest change of the output when every input moves by NUDGE_ULPS units in the last place
(random signs, DRAWS draws), times MARGIN. Far from a singular configuration that is a few ulps
of the output; near one it grows with the condition number, as rounding elsewhere would.
An outcome (a status) that such a nudge changes here is on a boundary: another machine may land
on either side of it, and `Nudged.borderline` says so.
"""
import numpy as np

EPS = np.finfo(float).eps
NUDGE_ULPS = 4     # inputs moved by a few roundings: what a different operation order gives
DRAWS = 4          # random sign patterns per input set
MARGIN = 8         # the spread of DRAWS draws, not its maximum: room for the draws not made


class Nudged:
    """``call(*args) -> (status, outputs...)`` at args and at DRAWS nudged copies of them:
    ``.status`` and ``.outputs`` at args, ``.borderline`` (a nudge changed the status) and
    ``.spread[k]`` (the largest change of output k under a nudge, where the status held)."""

    def __init__(self, call, *args, seed=0):
        rng = np.random.default_rng(seed)
        self.status, *self.outputs = call(*args)
        self.outputs = [np.array(o, dtype=float, copy=True) for o in self.outputs]
        self.spread = [0.0] * len(self.outputs)
        self.borderline = False
        for _ in range(DRAWS):
            nudged = [np.asarray(a, dtype=float) * (1 + NUDGE_ULPS * EPS * rng.choice((-1.0, 1.0), np.shape(a)))
                      for a in args]
            status, *outputs = call(*nudged)
            if status != self.status:
                self.borderline = True
                continue
            for k, (a, b) in enumerate(zip(self.outputs, outputs)):
                with np.errstate(invalid="ignore"):
                    change = np.abs(np.asarray(b, dtype=float) - a)
                self.spread[k] = max(self.spread[k], float(np.nanmax(change, initial=0.0)))

    def tolerance(self, k, floor):
        """The difference output k may show against a value stored elsewhere: MARGIN x its
        spread, at least ``floor``."""
        return max(MARGIN * self.spread[k], floor)

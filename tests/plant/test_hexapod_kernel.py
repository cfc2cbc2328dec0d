"""The C Kane kernel (plant/c/hexapod.c through plant.hexapod.kernel) against the numba kernel it
replaced (git revision 73017ff, plant/hexapod/kernel.py + plant/linalg.py), state by state: the
port must keep every term, so both agree to rounding. The numba kernel's inputs and
outputs are stored in tests/golden/kernel_c_numba.npz (150 random states per case, where
the comparison against live numba used 300); regenerate with
tests/golden/make_numba_golden.py (needs numba, the `bench` extra, and the git history)."""
from pathlib import Path

import numpy as np
import pytest

from plant.hexapod import kernel as kane
from plant.hexapod.model import StewartParams

GOLDEN = Path(__file__).resolve().parents[1] / "golden" / "kernel_c_numba.npz"
RTOL = 1e-13
PARAMS = StewartParams.paper()
ARGS = (PARAMS.base_joints, PARAMS.platform_joints, PARAMS.kernel_data)
BASE_MODES = (kane.BASE_NONE, kane.BASE_GRAVITY, kane.BASE_FULL)
OUTPUTS = ("M", "h", "J", "ldot", "length", "out", "det")


@pytest.fixture(scope="module")
def numba_golden():
    """The arrays of GOLDEN: inputs, and what the numba kernel returned for them."""
    with np.load(GOLDEN) as golden:
        return dict(golden)


def numba_output(golden, key, name, solve):
    """The numba kernel's ``name`` for ``solve``: stored once under <key>_<name> (the ID's),
    under <key>_<name>_<solve> for a solve whose values differ."""
    return golden.get(f"{key}_{name}_{solve}", golden[f"{key}_{name}"])


def run_kernel(solve, base_mode, legs, twist_speeds, pose, rate, arg, base):
    n = pose.shape[0]
    out = [np.empty((n, 6, 6)), np.empty((n, 6)), np.empty((n, 6, 6)), np.empty((n, 6)),
           np.empty((n, 6)), np.full((n, 6), np.nan), np.empty(n)]
    kane.kane(*ARGS, pose, rate, arg, *base, base_mode, legs, twist_speeds, solve, *out)
    return out


class _DetKept(kane.StateInverseDynamicsCall):
    """The controller's single-state call with det J kept: a det_min of inf makes every
    call hand its det to ``singular``."""

    def singular(self, det):
        self.det = det


def assert_close(c, ref, what):
    """Each entry equal to RTOL of itself, or of 1e-2 RTOL of its state's largest entry
    when near 0 (the port keeps the operation order, so rounding differs little if at all)."""
    scale = np.max(np.abs(ref).reshape(ref.shape[0], -1), axis=1).reshape((-1,) + (1,) * (ref.ndim - 1))
    err = np.abs(c - ref) / np.maximum(np.maximum(np.abs(ref), 1e-2 * scale), 1e-300)
    assert np.all(np.isfinite(c) == np.isfinite(ref)), what
    assert np.nanmax(err) <= RTOL, f"{what}: relative difference {np.nanmax(err):.2e}"


@pytest.mark.parametrize("twist_speeds", [False, True])
@pytest.mark.parametrize("legs", [True, False])
@pytest.mark.parametrize("base_mode", BASE_MODES)
def test_batched_kernel_equals_numba(numba_golden, base_mode, legs, twist_speeds):
    """M, h, J, leg lengths and rates, det J and the ID / FD solutions on the stored random
    states (near home; a base far from the origin, tilted every way and moving fast)."""
    key = f"batched_{base_mode}_{int(legs)}_{int(twist_speeds)}"
    pose, rate, acc, *base = (numba_golden[f"{key}_{name}"] for name in
                              ("pose", "rate", "acc", "base_pose", "base_rate", "base_acc"))
    forces, n_states = numba_golden[f"{key}_forces"], pose.shape[0]
    for solve, arg in ((kane.ID, acc), (kane.FD, forces), (kane.TERMS, acc)):
        mine = run_kernel(solve, base_mode, legs, twist_speeds, pose, rate, arg, base)
        for c, name in zip(mine, OUTPUTS):
            if solve == kane.TERMS and name == "out":
                continue
            r = numba_output(numba_golden, key, name, solve)
            if name == "det":
                c, r = c[:, None], r[:, None]
            assert_close(c, r, f"solve {solve}: {name}")
        if solve == kane.ID and not twist_speeds:   # the controller's single-state entry point
            f, ln, ld = np.empty(6), np.empty(6), np.empty(6)
            single = _DetKept(kane.HexapodKernel(*ARGS), base_mode, legs, (f, ln, ld), np.inf)
            for n in range(0, n_states, 37):
                single(pose[n], rate[n], acc[n], base[0][n], base[1][n], base[2][n])
                assert single.det == mine[6][n]
                for a, k in ((f, 5), (ln, 4), (ld, 3)):
                    np.testing.assert_array_equal(a, mine[k][n])


@pytest.mark.parametrize("rk4", [True, False])
@pytest.mark.parametrize("base_mode", BASE_MODES)
def test_advance_fixed_equals_numba(numba_golden, base_mode, rk4):
    """advance_fixed (state, read-out, smallest |det J|, status) and rhs; the stroke
    bounds were drawn around the home lengths so that some steps end with STROKE."""
    g = {name: numba_golden[f"advance_{base_mode}_{int(rk4)}_{name}"] for name in
         ("x0", "inputs", "bounds", "substeps", "t0", "h", "x", "outputs", "det", "status", "rhs", "det_rhs")}
    statuses = set()
    for k in range(len(g["x0"])):
        inputs, t0 = g["inputs"][k], g["t0"][k]
        x, outputs = g["x0"][k].copy(), np.full((3, 6), np.nan)
        det, status = kane.advance_fixed(rk4, int(g["substeps"][k]), *ARGS, x, inputs, t0, g["h"][k], base_mode,
                                         True, g["bounds"][k], outputs)
        dx, det_rhs = kane.rhs(*ARGS, x, inputs[0:1], inputs[1:4], t0, t0 + 0.3e-3, base_mode, True)
        assert status == g["status"][k]
        statuses.add(int(status))
        for c, r, name in ((x, g["x"][k], "x"), (outputs, g["outputs"][k], "outputs"), (dx, g["rhs"][k], "rhs")):
            assert_close(c.reshape(1, -1), r.reshape(1, -1), name)
        assert det == pytest.approx(g["det"][k], rel=RTOL, abs=0)
        assert det_rhs == pytest.approx(g["det_rhs"][k], rel=RTOL, abs=0)
    assert {int(kane.OK), int(kane.STROKE)} <= statuses


def test_advance_fixed_failures_equal_numba(numba_golden):
    """NaN input (state left alone) and divergence give the same status and det."""
    for case in ("nan", "far"):
        x = numba_golden[f"failures_{case}_x0"].copy()
        det, status = kane.advance_fixed(True, 1, *ARGS, x, numba_golden[f"failures_{case}_inputs"], 0.0, 1e-3,
                                         kane.BASE_FULL, True, numba_golden["failures_bounds"], np.zeros((3, 6)))
        assert int(status) == numba_golden[f"failures_{case}_status"] == (
            kane.BAD_INPUT if case == "nan" else kane.DIVERGED)
        assert det == pytest.approx(numba_golden[f"failures_{case}_det"], rel=RTOL, abs=0)
        np.testing.assert_allclose(x, numba_golden[f"failures_{case}_x"], rtol=RTOL)

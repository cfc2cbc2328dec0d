"""The C Kane kernel (plant/c/hexapod.c through plant.kane) against the numba kernel it
replaced (git revision 73017ff, plant/hexapod/kernel.py + plant/linalg.py), state by state: the
port must keep every term, so both agree to rounding. Runs only where numba is
importable (the optional extra `bench`) and the repository's history is at hand."""
import importlib
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from plant.hexapod import kernel as kane
from plant.hexapod.model import HOME_POSE, StewartParams

REVISION = "73017ff"
ROOT = Path(__file__).resolve().parents[2]
N = 300
RTOL = 1e-13
PARAMS = StewartParams.paper()
ARGS = (PARAMS.base_joints, PARAMS.platform_joints, PARAMS.kernel_data)
BASE_MODES = (kane.BASE_NONE, kane.BASE_GRAVITY, kane.BASE_FULL)


@pytest.fixture(scope="module")
def numba_kane(tmp_path_factory):
    """plant/hexapod/kernel.py of REVISION as the module ``kane_numba_<rev>.kane`` (its linalg beside it)."""
    pytest.importorskip("numba")
    package = tmp_path_factory.mktemp("old") / f"kane_numba_{REVISION}"
    package.mkdir()
    (package / "__init__.py").write_text("")
    for name in ("kane.py", "linalg.py"):
        try:
            text = subprocess.run(["git", "show", f"{REVISION}:plant/{name}"], cwd=ROOT, check=True,
                                  capture_output=True, text=True).stdout
        except (OSError, subprocess.CalledProcessError) as err:
            pytest.skip(f"git revision {REVISION} not available: {err}")
        (package / name).write_text(text)
    sys.path.insert(0, str(package.parent))
    try:
        yield importlib.import_module(f"{package.name}.kane")
    finally:
        sys.path.remove(str(package.parent))


def states(rng, n):
    """Platform states near home (as in test_stewart_truth) and a base far from the
    origin, tilted every way and moving fast, so every base term is large."""
    pose = HOME_POSE + np.c_[rng.uniform(-0.05, 0.05, (n, 3)), rng.uniform(-0.04, 0.04, (n, 3))]
    rate = np.c_[rng.uniform(-0.1, 0.1, (n, 3)), rng.uniform(-0.5, 0.5, (n, 3))]
    acc = np.c_[rng.uniform(-1.0, 1.0, (n, 3)), rng.uniform(-5.0, 5.0, (n, 3))]
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    base_pose = np.c_[direction * rng.uniform(20.0, 40.0, (n, 1)), rng.uniform(-1.3, 1.3, n),
                      rng.uniform(-1.0, 1.0, n), rng.uniform(-np.pi, np.pi, n)]
    base_rate = np.c_[rng.uniform(-2.0, 2.0, (n, 3)), rng.uniform(-1.0, 1.0, (n, 3))]
    base_acc = np.c_[rng.uniform(-3.0, 3.0, (n, 3)), rng.uniform(-3.0, 3.0, (n, 3))]
    return pose, rate, acc, base_pose, base_rate, base_acc


def run_kernel(module, solve, base_mode, legs, twist_speeds, pose, rate, arg, base):
    n = pose.shape[0]
    out = [np.empty((n, 6, 6)), np.empty((n, 6)), np.empty((n, 6, 6)), np.empty((n, 6)),
           np.empty((n, 6)), np.full((n, 6), np.nan), np.empty(n)]
    module.kane(*ARGS, pose, rate, arg, *base, base_mode, legs, twist_speeds, solve, *out)
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
def test_batched_kernel_equals_numba(numba_kane, base_mode, legs, twist_speeds):
    """M, h, J, leg lengths and rates, det J and the ID / FD solutions on N random states."""
    rng = np.random.default_rng(9 + 3 * base_mode + legs + 7 * twist_speeds)
    pose, rate, acc, *base = states(rng, N)
    forces = rng.uniform(-8e3, 8e3, (N, 6))
    for solve, arg in ((kane.ID, acc), (kane.FD, forces), (kane.TERMS, acc)):
        mine = run_kernel(kane, solve, base_mode, legs, twist_speeds, pose, rate, arg, base)
        ref = run_kernel(numba_kane, solve, base_mode, legs, twist_speeds, pose, rate, arg, base)
        for c, r, name in zip(mine, ref, ("M", "h", "J", "ldot", "length", "out", "det")):
            if solve == kane.TERMS and name == "out":
                continue
            if name == "det":
                c, r = c[:, None], r[:, None]
            assert_close(c, r, f"solve {solve}: {name}")
        if solve == kane.ID and not twist_speeds:   # the controller's single-state entry point
            f, ln, ld = np.empty(6), np.empty(6), np.empty(6)
            single = _DetKept(kane.HexapodKernel(*ARGS), base_mode, legs, (f, ln, ld), np.inf)
            for n in range(0, N, 37):
                single(pose[n], rate[n], acc[n], base[0][n], base[1][n], base[2][n])
                assert single.det == mine[6][n]
                for a, k in ((f, 5), (ln, 4), (ld, 3)):
                    np.testing.assert_array_equal(a, mine[k][n])


@pytest.mark.parametrize("rk4", [True, False])
@pytest.mark.parametrize("base_mode", BASE_MODES)
def test_advance_fixed_equals_numba(numba_kane, base_mode, rk4):
    """advance_fixed (state, read-out, smallest |det J|, status) and rhs; the stroke
    bounds are drawn around the home lengths so that some steps end with STROKE."""
    rng = np.random.default_rng(100 + base_mode + 3 * rk4)
    n = 60
    pose, rate, _, *base = states(rng, n)
    twist = np.c_[rate[:, :3], rng.uniform(-0.5, 0.5, (n, 3))]
    statuses = set()
    for k in range(n):
        inputs = np.vstack([rng.uniform(-8e3, 8e3, 6), base[0][k], base[1][k], base[2][k]])
        bounds = PARAMS.home_lengths + np.array([[-0.04], [0.04]]) * rng.uniform(0.5, 1.5)
        substeps, t0, h = 1 + k % 3, rng.uniform(0, 10), 1e-3 * (1 + k % 4)
        results = []
        for module in (kane, numba_kane):
            x, outputs = np.r_[pose[k], twist[k]], np.full((3, 6), np.nan)
            det, status = module.advance_fixed(rk4, substeps, *ARGS, x, inputs, t0, h, base_mode, True, bounds,
                                               outputs)
            dx, det_rhs = module.rhs(*ARGS, x, inputs[0:1], inputs[1:4], t0, t0 + 0.3e-3, base_mode, True)
            results.append((x, outputs, det, status, dx, det_rhs))
        (x, outputs, det, status, dx, det_rhs), ref = results
        assert status == ref[3]
        statuses.add(int(status))
        for c, r, name in ((x, ref[0], "x"), (outputs, ref[1], "outputs"), (dx, ref[4], "rhs")):
            assert_close(c.reshape(1, -1), r.reshape(1, -1), name)
        assert det == pytest.approx(ref[2], rel=RTOL) and det_rhs == pytest.approx(ref[5], rel=RTOL)
    assert {int(kane.OK), int(kane.STROKE)} <= statuses


def test_advance_fixed_failures_equal_numba(numba_kane):
    """NaN input (state left alone) and divergence give the same status and det."""
    inputs = np.zeros((4, 6))
    bounds = PARAMS.home_lengths + np.array([[-1.0], [1.0]])
    for case in ("nan", "far"):
        got = []
        for module in (kane, numba_kane):
            x = np.r_[HOME_POSE, np.zeros(6)]
            ins = inputs.copy()
            if case == "nan":
                ins[2, 4] = np.nan
            else:
                x[6] = 2e5   # 200 m in 1 ms: past the 100 m divergence bound
            det, status = module.advance_fixed(True, 1, *ARGS, x, ins, 0.0, 1e-3, kane.BASE_FULL, True, bounds,
                                               np.zeros((3, 6)))
            got.append((int(status), det, x))
        assert got[0][0] == got[1][0] == (kane.BAD_INPUT if case == "nan" else kane.DIVERGED)
        assert got[0][1] == pytest.approx(got[1][1], rel=RTOL)
        np.testing.assert_allclose(got[0][2], got[1][2], rtol=RTOL)

"""Write the golden arrays of the kernels the C kernels were ported from:

    tests/golden/kernel_c_numba.npz             for tests/plant/test_hexapod_kernel.py
    tests/golden/mechanism3t_kernel_c_numba.npz for tests/plant/test_mechanism3t_kernel.py
    tests/golden/telescope_c_numba.npz          for tests/plant/test_telescope_kernel.py

Each file holds the inputs those tests give the C kernels and what the old kernels of git
revision 73017ff returned for them: the numba Kane kernel (plant/kane.py + linalg.py), the
numba 3T-mechanism kernel (plant/mechanism3t_kernel.py + linalg.py) and the numpy telescope
(plant/telescope.py, trajectory.py, fmu_src/telescope_fmu.py; numpy, not numba, but the
same kind of reference). The tests read the files and need neither numba nor git.

Run by hand, from a clone with the git history (the revision must be reachable) and a venv
with the ``bench`` extra (numba):

    .venv/bin/pip install -c constraints.txt -e '.[dev,bench]'
    .venv/bin/python tests/golden/make_numba_golden.py [kernel_c] [mechanism3t_kernel_c] [telescope_c]

(no names: all three; telescope_c alone needs no numba). The old modules are loaded from
``git show 73017ff:<path>`` into a temporary package, as the tests did before; the inputs
come from the same seeded generators and sizes as before, except where a file would pass
~2 MB: 150 Kane states per case instead of 300 (KANE_N), and fewer times per telescope
profile (TELESCOPE_*). The FMU rows' non-axis columns are the old FMU's from today's C
axes (as the test did), so they hold the C axes of the day they were written. Rerun after a
change of the inputs a test wants; the old kernels never change, so the outputs only
change with the inputs (or with numba/numpy rounding, which the tests' tolerances cover).

Layout: flat names ``<test>_<what>``; a list of variable-length arrays is stored
concatenated along axis 0 as ``<name>`` with ``<name>_offsets`` (see ``ragged``); strings
(error types and messages) as numpy unicode arrays, so ``np.load`` needs no pickle.
"""
import importlib
import subprocess
import sys
import tempfile
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np

REVISION = "73017ff"
ROOT = Path(__file__).resolve().parents[2]
GOLDEN = Path(__file__).resolve().parent

# tests/plant/test_hexapod_kernel.py
KANE_N = 150            # random states per (base mode, legs, twist speeds); the old test's 300: 3.8 MB
KANE_ADVANCE_N = 60     # advance_fixed runs per (base mode, rk4)
# tests/plant/test_mechanism3t_kernel.py: ~1000 states as before, 150 advance runs
M3T_ADVANCE_N = 150
# tests/plant/test_telescope_kernel.py: the old test's 60 / 80 parameter sets with 700 / 1800 times
# each would be ~60 MB; these keep the parameter sets and every phase at ~2 MB (plus 16
# times closing in on each transit, where the fewer even times would miss the keyhole)
TELESCOPE_SLEW_CASES, TELESCOPE_SLEW_GRID = 60, 50
TELESCOPE_SIDEREAL_CASES, TELESCOPE_SIDEREAL_RANDOM, TELESCOPE_SIDEREAL_GRID = 80, 12, 40
TELESCOPE_PAPER_GRID = 150
TELESCOPE_FMU_STRIDE = 10   # every 10th row of each evaluated block is stored


def git_show(path, revision=REVISION):
    return subprocess.run(["git", "-C", str(ROOT), "show", f"{revision}:{path}"], check=True,
                          capture_output=True, text=True).stdout


def import_package(directory, name, files, module):
    """Write ``files`` ({file name: text}) as package ``name`` in ``directory``, import
    ``name.module`` and return it."""
    package = Path(directory) / name
    package.mkdir(exist_ok=True)
    (package / "__init__.py").write_text("")
    for file, text in files.items():
        (package / file).write_text(text)
    sys.path.insert(0, str(directory))
    try:
        return importlib.import_module(f"{name}.{module}")
    finally:
        sys.path.remove(str(directory))


def load_numba_kane(directory, revision=REVISION):
    """plant/kane.py of ``revision`` as ``kane_numba_<rev>.kane`` (its linalg beside it)."""
    return import_package(directory, f"kane_numba_{revision}",
                          {f: git_show(f"plant/{f}", revision) for f in ("kane.py", "linalg.py")}, "kane")


def load_numba_kernel(directory, revision=REVISION):
    """plant/mechanism3t_kernel.py and plant/linalg.py of ``revision`` imported as a package in
    ``directory`` (their other imports point at today's plant). Needs git and numba; also
    used by benchmarks/bench_mechanism3t.py."""
    files = {}
    for file in ("mechanism3t_kernel.py", "linalg.py"):
        source = git_show(f"plant/{file}", revision)
        source = source.replace("from .errors import", "from movingbase.plant.errors import")
        source = source.replace("from .mechanism3t import", "from movingbase.plant.mechanism3t import")
        files[file] = source
    return import_package(directory, f"m3t_numba_{revision}", files, "mechanism3t_kernel")


def load_old_telescope(directory, revision=REVISION):
    """telescope, trajectory and the FMU module telescope_fmu of ``revision`` as the package
    ``old73017ff`` (the FMU module importing them and the slave base of that revision, and
    HOME_POSE, S_BAND_POSE from today's plant.stewart)."""
    files = {}
    for name in ("errors", "rotations", "trajectory", "telescope", "slave", "telescope_fmu"):
        text = git_show(("fmu_src/" if name in ("slave", "telescope_fmu") else "plant/") + name + ".py", revision)
        if name == "telescope_fmu":
            text = (text.replace("from plant import telescope", "from old73017ff import telescope")
                        .replace("from plant.trajectory import", "from old73017ff.trajectory import")
                        .replace("from fmu_src.slave import", "from old73017ff.slave import")
                        .replace("from plant.stewart import", "from movingbase.plant.stewart import"))
            assert "from plant" not in text and "from fmu_src" not in text
        files[f"{name}.py"] = text
    import_package(directory, "old73017ff", files, "telescope")
    sys.path.insert(0, str(directory))
    try:
        for name in ("trajectory", "telescope_fmu"):
            importlib.import_module(f"old73017ff.{name}")
        return importlib.import_module("old73017ff")
    finally:
        sys.path.remove(str(directory))


def ragged(name, arrays):
    """{name: the arrays concatenated on axis 0, name_offsets: where each starts and ends}."""
    offsets = np.r_[0, np.cumsum([len(a) for a in arrays])]
    return {name: np.concatenate(arrays), f"{name}_offsets": offsets}


def write(name, arrays):
    path = GOLDEN / f"{name}_numba.npz"
    np.savez_compressed(path, **arrays)
    print(f"wrote {path.relative_to(ROOT)}: {len(arrays)} arrays, {path.stat().st_size / 1e6:.2f} MB")


# --- tests/plant/test_hexapod_kernel.py --------------------------------------------------------

def kane_states(rng, n):
    """Platform states near home (as in test_stewart_truth) and a base far from the
    origin, tilted every way and moving fast, so every base term is large."""
    from movingbase.plant.stewart import HOME_POSE
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


KANE_OUTPUTS = ("M", "h", "J", "ldot", "length", "out", "det")


def kernel_c(directory):
    from movingbase.plant import kane
    from movingbase.plant.stewart import HOME_POSE, StewartParams
    old = load_numba_kane(directory)
    params = StewartParams.paper()
    args = (params.base_joints, params.platform_joints, params.kernel_data)
    arrays = {}
    for base_mode in (kane.BASE_NONE, kane.BASE_GRAVITY, kane.BASE_FULL):
        for legs in (True, False):
            for twist_speeds in (False, True):
                key = f"batched_{base_mode}_{int(legs)}_{int(twist_speeds)}"
                rng = np.random.default_rng(9 + 3 * base_mode + legs + 7 * twist_speeds)
                inputs = kane_states(rng, KANE_N)
                forces = rng.uniform(-8e3, 8e3, (KANE_N, 6))
                for name, value in zip(("pose", "rate", "acc", "base_pose", "base_rate", "base_acc"), inputs):
                    arrays[f"{key}_{name}"] = value
                arrays[f"{key}_forces"] = forces
                pose, rate, acc, *base = inputs
                for solve, arg in ((kane.ID, acc), (kane.FD, forces), (kane.TERMS, acc)):
                    # NaN-filled, so that an output the kernel leaves alone shows
                    out = [np.full((KANE_N, 6, 6), np.nan), np.full((KANE_N, 6), np.nan),
                           np.full((KANE_N, 6, 6), np.nan), np.full((KANE_N, 6), np.nan),
                           np.full((KANE_N, 6), np.nan), np.full((KANE_N, 6), np.nan), np.full(KANE_N, np.nan)]
                    old.kane(*args, pose, rate, arg, *base, base_mode, legs, twist_speeds, solve, *out)
                    for value, name in zip(out, KANE_OUTPUTS):
                        if solve == kane.TERMS and name == "out":
                            continue
                        # <key>_<name> holds the first solve's (ID's) values, <key>_<name>_<solve>
                        # a later solve's where they differ (det, out)
                        if f"{key}_{name}" not in arrays:
                            arrays[f"{key}_{name}"] = value
                        elif not np.array_equal(value, arrays[f"{key}_{name}"], equal_nan=True):
                            arrays[f"{key}_{name}_{solve}"] = value
    for base_mode in (kane.BASE_NONE, kane.BASE_GRAVITY, kane.BASE_FULL):
        for rk4 in (True, False):
            key = f"advance_{base_mode}_{int(rk4)}"
            rng = np.random.default_rng(100 + base_mode + 3 * rk4)
            n = KANE_ADVANCE_N
            pose, rate, _, *base = kane_states(rng, n)
            twist = np.c_[rate[:, :3], rng.uniform(-0.5, 0.5, (n, 3))]
            rows = {name: [] for name in ("x0", "inputs", "bounds", "substeps", "t0", "h",
                                          "x", "outputs", "det", "status", "rhs", "det_rhs")}
            for k in range(n):
                inputs = np.vstack([rng.uniform(-8e3, 8e3, 6), base[0][k], base[1][k], base[2][k]])
                bounds = params.home_lengths + np.array([[-0.04], [0.04]]) * rng.uniform(0.5, 1.5)
                substeps, t0, h = 1 + k % 3, rng.uniform(0, 10), 1e-3 * (1 + k % 4)
                x0 = np.r_[pose[k], twist[k]]
                x, outputs = x0.copy(), np.full((3, 6), np.nan)
                det, status = old.advance_fixed(rk4, substeps, *args, x, inputs, t0, h, base_mode, True, bounds,
                                                outputs)
                dx, det_rhs = old.rhs(*args, x, inputs[0:1], inputs[1:4], t0, t0 + 0.3e-3, base_mode, True)
                for name, value in zip(rows, (x0, inputs, bounds, substeps, t0, h, x, outputs, det, int(status),
                                              dx, det_rhs)):
                    rows[name].append(value)
            for name, values in rows.items():
                arrays[f"{key}_{name}"] = np.array(values)
    bounds = params.home_lengths + np.array([[-1.0], [1.0]])
    arrays["failures_bounds"] = bounds
    for case in ("nan", "far"):
        x, inputs = np.r_[HOME_POSE, np.zeros(6)], np.zeros((4, 6))
        if case == "nan":
            inputs[2, 4] = np.nan
        else:
            x[6] = 2e5   # 200 m in 1 ms: past the 100 m divergence bound
        arrays[f"failures_{case}_x0"], arrays[f"failures_{case}_inputs"] = x.copy(), inputs
        det, status = old.advance_fixed(True, 1, *args, x, inputs, 0.0, 1e-3, kane.BASE_FULL, True, bounds,
                                        np.zeros((3, 6)))
        arrays[f"failures_{case}_status"], arrays[f"failures_{case}_det"] = np.array(int(status)), np.array(det)
        arrays[f"failures_{case}_x"] = x
    return arrays


# --- tests/plant/test_mechanism3t_kernel.py ----------------------------------------------

M3T_WRAPPERS = ("dynamics_terms", "slider_forces", "forward_dynamics", "forward_branch")


def m3t_states(rng, P):
    """~1000 configurations: near the paper's, on every inverse-position branch of random O',
    and over a box far wider than the workspace (unreachable and singular ones included)."""
    from movingbase.plant import mechanism3t as m3t
    inverse = []
    while len(inverse) < 400:
        p = rng.uniform([-0.1, -0.32, P.l1 + P.l5], [0.38, 0.45, P.l1 + P.l5 + P.l4])
        try:
            inverse.extend(m3t.inverse_position(P, p))
        except m3t.UnreachableError:
            pass
    near_sin = [[x, 0.0, P.d] for x in np.linspace(-3e-16, 3e-16, 7)]   # sin theta -> 0
    rho_ref = np.array(m3t.PAPER_REFERENCE_RHO_MM) * m3t.MM
    return np.r_[rho_ref + rng.uniform(-0.03, 0.03, (300, 3)), np.array(inverse[:400]),
                 rng.uniform([-0.3, -0.5, -0.5], [0.4, 0.5, 0.5], (300, 3)), near_sin]


def mechanism3t_kernel_c(directory):
    from movingbase.plant import mechanism3t as m3t
    old = load_numba_kernel(directory)
    P = m3t.Mechanism1Params.paper()
    rho_ref = np.array(m3t.PAPER_REFERENCE_RHO_MM) * m3t.MM
    pa = old.pack(P)
    arrays = {"pack": pa}
    rng = np.random.default_rng(9)
    rho_all = m3t_states(rng, P)
    rows = {}

    def add(name, value):
        rows.setdefault(name, []).append(value)

    for rho in rho_all:
        rho_dot, rho_ddot, forces = rng.normal(0, 0.3, 3), rng.normal(0, 3.0, 3), rng.normal(0, 100.0, 3)
        add("rho", rho), add("rho_dot", rho_dot), add("rho_ddot", rho_ddot), add("forces", forces)
        for mode in (1, -1):   # rows of every per-mode array: state 0 mode 1, state 0 mode -1, state 1 ...
            p = np.full(3, np.nan)
            add("position_status", old.position_kernel(pa, rho, mode, p)), add("position_p", p)
            terms = [np.full((3, 3), np.nan), np.full(3, np.nan), np.full(3, np.nan)]
            add("terms_status", old.terms(pa, rho, rho_dot, mode, *terms))
            for k, value in enumerate(terms):
                add(f"terms_{k}", value)
            f = np.full(3, np.nan)
            add("slider_forces_status", old.slider_forces_kernel(pa, rho, rho_dot, rho_ddot, mode, f))
            add("slider_forces_out", f)
            a = np.full(3, np.nan)
            add("forward_dynamics_status", old.forward_dynamics_kernel(pa, rho, rho_dot, forces, mode, a))
            add("forward_dynamics_out", a)
            status, xdot = old.rhs_kernel(pa, np.r_[rho, rho_dot], forces, mode)
            if status != old.OK:   # an unwritten np.empty: NaN, so that a rerun writes the same file
                xdot = np.full(6, np.nan)
            add("rhs_status", status), add("rhs_xdot", xdot)
            for name, args in (("dynamics_terms", (rho, rho_dot)), ("slider_forces", (rho, rho_dot, rho_ddot)),
                               ("forward_dynamics", (rho, rho_dot, forces)), ("forward_branch", (rho,))):
                try:
                    value = getattr(old, name)(P, *args, mode)
                    kind, message = "ok", ""
                except (m3t.InvalidInputError, m3t.UnreachableError, m3t.SingularConfigurationError) as error:
                    kind, message = type(error).__name__, str(error)
                    value = ((np.full((3, 3), np.nan), np.full(3, np.nan), np.full(3, np.nan))
                             if name == "dynamics_terms" else np.full(3, np.nan))
                add(f"{name}_kind", kind), add(f"{name}_message", message)
                if name == "dynamics_terms":
                    for k, v in enumerate(value):
                        add(f"{name}_{k}", v)
                else:
                    add(f"{name}_value", value)
    rng = np.random.default_rng(4)
    for _ in range(M3T_ADVANCE_N):
        x0 = np.r_[rho_ref + rng.uniform(-0.05, 0.05, 3), rng.normal(0, 0.2, 3)]
        forces = rng.normal(0, 400.0, 3)
        substeps, dt, rk4 = int(rng.integers(1, 60)), float(rng.uniform(1e-4, 5e-3)), bool(rng.integers(2))
        status, x = old.advance_fixed(pa, x0, forces, 1, rk4, substeps, dt)
        for name, value in (("x0", x0), ("forces", forces), ("substeps", substeps), ("dt", dt), ("rk4", rk4),
                            ("status", status), ("x", x)):
            add(f"advance_{name}", value)
    arrays.update({name: np.array(values) for name, values in rows.items()})
    return arrays


# --- tests/plant/test_telescope_kernel.py -------------------------------------------------------

DEG = np.pi / 180
TELESCOPE_FIELDS = ("latitude", "longitude", "lever_arm", "az_rate_max", "az_acc_max", "el_rate_max",
                    "el_acc_max", "b_y", "c_y", "b_z", "c_z")
J2000_ISH = datetime(2000, 1, 1, tzinfo=timezone.utc)


def random_params(rng):
    """Keyword values of a TelescopeParams: every field away from the defaults."""
    return dict(latitude=rng.uniform(-85, 85) * DEG, longitude=rng.uniform(-180, 180) * DEG,
                lever_arm=rng.choice([0.0, rng.uniform(0, 40)]),
                az_rate_max=rng.uniform(0.1, 3) * DEG, az_acc_max=rng.uniform(0.05, 2) * DEG,
                el_rate_max=rng.uniform(0.1, 3) * DEG, el_acc_max=rng.uniform(0.05, 2) * DEG,
                b_y=rng.uniform(-0.03, 0.03), c_y=rng.uniform(-0.03, 0.03),
                b_z=rng.uniform(-0.03, 0.03), c_z=rng.uniform(-0.03, 0.03),
                home=tuple(rng.uniform(-0.1, 0.1, 6) + [0, 0, -2.68, 0, 0, 0]))


def params_rows(values):
    """(n, 17) rows of TelescopeParams keyword values: TELESCOPE_FIELDS, then home."""
    return np.array([[v[f] for f in TELESCOPE_FIELDS] + list(v["home"]) for v in values])


def axes_rows(axes):
    """(n, 7) [t, A, A', A'', E, E', E''] of an AxisMotion."""
    return np.column_stack([axes.t, axes.A, axes.A_dot, axes.A_ddot, axes.E, axes.E_dot, axes.E_ddot])


def old_stages(old, old_params, old_axes, astronomical=True):
    """The old base_motion (n, 3, 6), base_twist (n, 4, 3) and reference_pose (n, 3, 6) of
    the old axes, read as astronomical Az (slew, sidereal: the test's ``astronomical``) or
    as they are (the paper's)."""
    from types import SimpleNamespace
    if astronomical:
        old_axes = SimpleNamespace(t=old_axes.t, A=np.pi - old_axes.A, A_dot=-old_axes.A_dot,
                                   A_ddot=-old_axes.A_ddot, E=old_axes.E, E_dot=old_axes.E_dot,
                                   E_ddot=old_axes.E_ddot)
    return {what: np.stack(f(old_params, old_axes), axis=1)
            for what, f in (("base_motion", old.telescope.base_motion), ("base_twist", old.telescope.base_twist),
                            ("reference_pose", old.telescope.reference_pose))}


def telescope_c(directory):
    from movingbase.fmu_src import telescope_fmu
    from movingbase.plant import telescope
    old = load_old_telescope(directory)
    arrays = {}

    def motion(prefix, cases):
        """Ragged arrays of the cases' old axes and stages (None: the old call raised)."""
        done = [c for c in cases if c is not None]
        arrays.update(ragged(f"{prefix}_axes", [axes_rows(a) for a, _ in done]))
        for what in ("base_motion", "base_twist", "reference_pose"):
            arrays.update(ragged(f"{prefix}_{what}", [s[what] for _, s in done]))

    def call(f, *args):
        try:
            return f(*args), ""
        except Exception as exc:   # noqa: BLE001 - the tests require InvalidInputError of both
            assert type(exc).__name__ == "InvalidInputError", exc
            return None, str(exc)

    # slew
    rng = np.random.default_rng(1)
    values, ends, durations, times, messages, cases = [], [], [], [], [], []
    for _ in range(TELESCOPE_SLEW_CASES):
        v = random_params(rng)
        old_p = old.telescope.TelescopeParams(**v)
        start = (rng.uniform(-360, 360) * DEG, rng.uniform(0, 90) * DEG)   # none, triangular, long moves:
        target = (start[0] + rng.choice([0.0, rng.uniform(-0.5, 0.5), rng.uniform(-400, 400)]) * DEG,
                  rng.choice([start[1], rng.uniform(0, 90) * DEG, np.pi / 2, 0.0]))
        duration = old.telescope.slew_duration(old_p, start, target)
        corners = []   # phase boundaries of both axes exactly, and a grid around the whole move
        for (a0, a1), rate, acc in (((start[0], target[0]), old_p.az_rate_max, old_p.az_acc_max),
                                    ((start[1], target[1]), old_p.el_rate_max, old_p.el_acc_max)):
            *_, d = old.telescope._trapezoid(a1 - a0, rate, acc, np.zeros(1))
            t_acc = min(rate / acc, np.sqrt(abs(a1 - a0) / acc))
            corners += [t_acc, d - t_acc, d]
        t = np.unique(np.r_[np.linspace(-5, 1.2 * duration + 5, TELESCOPE_SLEW_GRID), corners, 0.0])
        axes, message = call(old.telescope.slew, old_p, start, target, t)
        values.append(v), ends.append(start + target), durations.append(duration), times.append(t)
        messages.append(message), cases.append(None if axes is None else (axes, old_stages(old, old_p, axes)))
    arrays.update(slew_params=params_rows(values), slew_ends=np.array(ends), slew_duration=np.array(durations),
                  slew_message=np.array(messages))
    arrays.update(ragged("slew_t", times))
    motion("slew", cases)

    # sidereal tracks and the local sidereal time
    rng = np.random.default_rng(2)
    values, transits, lsts, sources, starts, times, messages, cases = [], [], [], [], [], [], [], []
    for k in range(TELESCOPE_SIDEREAL_CASES):
        v = random_params(rng)
        old_p = old.telescope.TelescopeParams(**v)
        transit_s = int(rng.uniform(0, 1e9))
        transit = J2000_ISH + timedelta(seconds=transit_s)
        lst = old.telescope.local_sidereal_time(old_p, transit)
        lat, kind = old_p.latitude, k % 4
        if kind == 0:     # the keyhole: transits just south or north of the zenith
            dec = lat + rng.choice([-1, 1]) * rng.uniform(2e-6, 0.01)
        elif kind == 1:   # circumpolar over a whole day: both culminations, any unwrapping
            dec = np.sign(lat) * rng.uniform(min(90 - abs(lat) + 1, 89.5), 89.9) * DEG
        else:
            dec = rng.uniform(-89, 89) * DEG
        dec = float(np.clip(dec, -np.pi / 2, np.pi / 2))
        ra = lst + rng.uniform(-0.3, 0.3)
        span = 90000.0 if kind == 1 else rng.uniform(60, 8 * 3600)
        start_s = transit_s - int(span / 2)
        # random and even times, and times closing in on the transit (the keyhole's swing)
        t = np.unique(np.r_[rng.uniform(0, span, TELESCOPE_SIDEREAL_RANDOM),
                            np.linspace(0, span, TELESCOPE_SIDEREAL_GRID),
                            int(span / 2) + np.outer([-1, 1], np.geomspace(1e-3, 30, 8)).ravel()])
        axes, message = call(old.telescope.sidereal_track, old_p, ra, dec, J2000_ISH + timedelta(seconds=start_s), t)
        values.append(v), transits.append(transit_s), lsts.append(lst), sources.append((ra, dec))
        starts.append(start_s), times.append(t), messages.append(message)
        cases.append(None if axes is None else (axes, old_stages(old, old_p, axes)))
    arrays.update(sidereal_params=params_rows(values), sidereal_transit_s=np.array(transits),
                  sidereal_lst=np.array(lsts), sidereal_source=np.array(sources),
                  sidereal_start_s=np.array(starts), sidereal_message=np.array(messages))
    arrays.update(ragged("sidereal_t", times))
    motion("sidereal", cases)

    # the paper's manoeuvre and the quintic
    rng = np.random.default_rng(3)
    v = random_params(rng)
    old_p = old.telescope.TelescopeParams(**v)
    durations, times, cases, quintic_ends, quintics = [], [], [], [], []
    for T in (6.0, 0.37, 1234.5, rng.uniform(0.1, 100)):
        t = np.unique(np.r_[np.linspace(-1, T + 1, TELESCOPE_PAPER_GRID), 0.0, T, T / 2])
        axes = old.telescope.paper_manoeuvre(t, T)
        durations.append(T), times.append(t), cases.append((axes, old_stages(old, old_p, axes, False)))
        start, stop = rng.uniform(-3, 3, 5), rng.uniform(-3, 3, 5)
        quintic_ends.append((start, stop)), quintics.append(np.stack(old.trajectory.quintic(start, stop, T, t), 1))
    grid = np.linspace(-1, 7, 24).reshape(2, 3, 4)
    arrays.update(paper_params=params_rows([v]), paper_duration=np.array(durations),
                  paper_quintic_ends=np.array(quintic_ends),
                  paper_quintic_grid=np.stack(old.trajectory.quintic(0.5, 2.0, 6.0, grid)))
    arrays.update(ragged("paper_t", times))
    arrays.update(ragged("paper_quintic", quintics))
    motion("paper", cases)

    # the FMU's rows: the cases, their settings and the blocks of times they are evaluated at
    blocks = [(0.0, 0.0, 1)] + [(0.0, 1e-3, telescope_fmu.BLOCK), (3.7, 0.05, 500), (-2.0, 0.25, 200),
                                (1e4, 1.0, 1)]
    arrays.update(fmu_blocks=np.array(blocks), fmu_stride=np.array(TELESCOPE_FMU_STRIDE))
    arrays["fmu_cases"] = np.array(list(FMU_CASES))
    for c, (profile, settings) in enumerate(fmu_cases(telescope).values()):
        arrays.update(settings_arrays(f"fmu_{c}", profile, settings))
        new, previous = (initialised(module, profile, settings) for module in (telescope_fmu, old.telescope_fmu))
        rows = []
        for b, (t0, h, n) in enumerate(blocks):
            times = (t0 + h * np.arange(n))[::TELESCOPE_FMU_STRIDE if b else 1]
            # the old FMU's axis columns (paper: its yaw = A output as Az = 180 deg - A), and
            # the rest from today's C axes at these times: an ulp of E near the zenith is
            # magnified by the base terms (the stages are compared one by one above)
            axis = previous._evaluate(times)[:, 36:]
            if profile == 2:
                axis[:, 0], axis[:, 2] = np.pi - axis[:, 0], -axis[:, 2]
            c_axes = telescope._axes(new.params, new.motion, times)
            profile_at, previous.profile_at = previous.profile_at, lambda t: c_axes
            rest = previous._evaluate(times)[:, :36]
            previous.profile_at = profile_at
            rows.append(np.concatenate([rest, axis], axis=1))
        arrays.update(ragged(f"fmu_{c}_rows", rows))

    # invalid settings: the old messages
    arrays["invalid_cases"] = np.array(list(INVALID_CASES))
    for c, (profile, settings) in enumerate(invalid_cases(telescope).values()):
        arrays.update(settings_arrays(f"invalid_{c}", profile, settings))
        slave = old.telescope_fmu.TelescopeBase(instance_name="old")
        slave.profile = profile
        slave.settings.update(settings)
        try:
            slave.initialize()
            for k in range(3):
                slave._publish(k * 40.0, 40.0)
        except Exception as exc:   # noqa: BLE001 - the test requires an InvalidInputError
            assert type(exc).__name__ == "InvalidInputError", exc
            arrays[f"invalid_{c}_message"] = np.array(str(exc))
        else:
            raise AssertionError(f"no error for {profile} {settings}")
    return arrays


def initialised(module, profile, settings):
    slave = getattr(module, "Telescope", None) or module.TelescopeBase   # renamed after 0.2.0
    slave = slave(instance_name=module.__name__)
    slave.profile = profile
    slave.settings.update(settings)
    slave.initialize()
    return slave


def settings_arrays(prefix, profile, settings):
    """A case's profile and settings as arrays (the test reads its cases from them)."""
    return {f"{prefix}_profile": np.array(profile), f"{prefix}_names": np.array(list(settings), dtype=str),
            f"{prefix}_values": np.array(list(settings.values()), dtype=float)}


FMU_CASES = ("slew", "slew delayed, far", "sidereal keyhole", "sidereal delayed", "paper", "paper delayed")


def fmu_cases(telescope):
    """Name: (profile, settings) of the FMU's valid cases; the keyhole's source is today's."""
    return dict(zip(FMU_CASES, (
        (0, {}),
        (0, dict(start_azimuth=-3.0, target_azimuth=4.0, target_elevation=0.1, start_delay=7.25, lever_arm=31.0,
                 az_rate_max=0.02)),
        (1, dict(right_ascension=telescope.near_zenith_source(
            telescope.TelescopeParams.tianma(), datetime.fromtimestamp(1.7e9 + 60, timezone.utc))[0])),
        (1, dict(right_ascension=2.0, declination=0.9, utc_start=1.8e9 + 0.5, start_delay=100.0, latitude=0.6,
                 longitude=-1.2)),
        (2, dict(lever_arm=0.0)),
        (2, dict(lever_arm=3.0, paper_duration=2.5, start_delay=1.5)))))


INVALID_CASES = ("elevation", "dec", "zenith", "below horizon", "sets later", "duration")


def invalid_cases(telescope):
    """Name: (profile, settings) the FMU refuses."""
    return dict(zip(INVALID_CASES, (
        (0, dict(target_elevation=1.7)), (1, dict(declination=2.0)),
        (1, dict(declination=telescope.TelescopeParams.tianma().latitude)),
        (1, dict(declination=-1.4)),                       # never rises at 31 deg north
        (1, dict(declination=-0.5, start_delay=1e4)),      # sets while the block is evaluated
        (2, dict(paper_duration=0.0)))))


MAKERS = {"kernel_c": kernel_c, "mechanism3t_kernel_c": mechanism3t_kernel_c, "telescope_c": telescope_c}


def main(names):
    if set(names) - {"telescope_c"}:   # the old telescope is numpy
        import numba  # noqa: F401 - the old kernels need it; fail here rather than half-way
    for name in names:
        with tempfile.TemporaryDirectory() as directory:
            write(name, MAKERS[name](directory))


if __name__ == "__main__":
    main(sys.argv[1:] or list(MAKERS))

"""fmi3GetOutputDerivatives of the FMI 3.0 Telescope (fmu_src/native/fmi3_layer.c,
declared by the catalogue (fmu_src/catalogue.py, output_derivatives)): its base and reference motion are known
analytically, so a master may take their derivatives instead of extrapolating.

Truth: the derivatives against central finite differences of the FMU's own outputs
along the shipped slew (accelerating, cruising, decelerating), and against the chain
rule worked here by hand from the axis profile (plant.telescope.model.profile_axes):
roll = 90 deg - E, pitch = 0, yaw = A, p = L (cos E sin A, -cos E cos A, sin E)."""
import dataclasses
from ctypes import CFUNCTYPE, POINTER, c_double, c_int, c_int32, c_size_t, c_uint, c_void_p

import numpy as np
import pytest
from fmpy import read_model_description

from fmu_src import native_build
from plant.telescope import model as telescope
from scenarios.cosim import fmi
from scenarios.runs import runner
from tests.fmu_helpers import OPENED

GET_DERIVATIVES = CFUNCTYPE(c_int, c_void_p, POINTER(c_uint), c_size_t, POINTER(c_int32), POINTER(c_double), c_size_t)
H = 1e-3


@pytest.fixture(scope="module")
def slew():
    """The shipped slew's telescope parameters (SI) and its FMI 3.0 Telescope."""
    scenario, paths, descriptions, values = runner.prepare(runner.resolve("telescope_slew"), fmi_version=3)
    return values["base"], paths["base"]


def opened(path, values):
    inst = fmi.Instance(path, "base")
    inst.md3 = fmi.unpack(path)[0]
    OPENED.append(inst)
    inst.initialize(0.0, values)
    return inst


def derivatives(inst, names, order):
    """fmi3GetOutputDerivatives of ``names`` (FMI 3 variables), all of one order:
    (status, values)."""
    md = {v.name: v for v in inst.md3.modelVariables}
    vrs = [md[n].valueReference for n in names]
    count = sum(int(np.prod([int(d.start) for d in md[n].dimensions])) if md[n].dimensions else 1 for n in names)
    out = (c_double * count)()
    call = GET_DERIVATIVES(("fmi3GetOutputDerivatives", inst.fmu.dll))
    status = call(inst.fmu.component, (c_uint * len(vrs))(*vrs), len(vrs), (c_int32 * len(vrs))(*[order] * len(vrs)),
                  out, count)
    return status, np.array(out)


POSE = [f"base_pose[{k}]" for k in range(1, 7)] + [f"reference_pose[{k}]" for k in range(1, 7)]


def test_the_description_declares_what_the_layer_answers(slew):
    md = read_model_description(str(slew[1]))
    assert md.coSimulation.maxOutputDerivativeOrder == 2
    variables = {v.name: v for v in md.modelVariables}
    assert variables["base_rate[4]"].derivative.name == "base_pose[4]"
    assert variables["axis_acc[2]"].derivative.name == "axis_rate[2]"
    assert read_model_description(str(native_build.ensure_native3(["hexapod_plant_fmu"])["hexapod_plant_fmu"])) \
        .coSimulation.maxOutputDerivativeOrder in (None, 0)


def test_derivatives_are_the_finite_differences_and_the_chain_rule(slew):
    """Along the slew (start_delay 5 s; t in the acceleration, cruise and deceleration
    phases): order 1 and 2 of the base and reference pose against central differences of
    the outputs (error O(h^2) of the third/fourth derivative: 1e-6 of the scale here),
    order 1 of the pose and order 2 of its angles against the hand-worked chain rule."""
    values, path = slew
    inst = opened(path, values)
    params = dataclasses.replace(telescope.TelescopeParams.tianma(), lever_arm=values["lever_arm"])
    lever = values["lever_arm"]
    times = {5.5, 12.0, 30.0, 52.0}
    k, rows = 0, {}
    while k * H < 52.0 + 2 * H:
        t = k * H
        inst.do_step(t, H)
        k += 1
        t = k * H
        if any(abs(t - c) <= 1.5 * H for c in times):
            pose = np.array([inst.get_real(n) for n in POSE])
            rows[round(t / H)] = (pose, derivatives(inst, POSE, 1), derivatives(inst, POSE, 2))
    checked = 0
    for centre in sorted(times):
        c = round(centre / H)
        pose, (s1, d1), (s2, d2) = rows[c]
        assert s1 == 0 and s2 == 0
        fd1 = (rows[c + 1][0] - rows[c - 1][0]) / (2 * H)
        fd2 = (rows[c + 1][0] - 2 * pose + rows[c - 1][0]) / H ** 2
        scale1, scale2 = np.max(np.abs(d1)) + 1e-9, np.max(np.abs(d2)) + 1e-9
        assert np.max(np.abs(d1 - fd1)) <= 1e-5 * scale1 + 1e-12, centre
        assert np.max(np.abs(d2 - fd2)) <= 1e-3 * scale2 + 1e-9, centre
        # the chain rule by hand, from the command axes at t - start_delay
        motion = telescope.motion_profile("slew", (values["start_azimuth"], values["start_elevation"]),
                                          (values["target_azimuth"], values["target_elevation"]),
                                          start_delay=values["start_delay"])
        A, A1, A2, E, E1, E2 = telescope.profile_axes(params, motion, c * H)[0]
        hand1 = [lever * (-np.sin(E) * E1 * np.sin(A) + np.cos(E) * np.cos(A) * A1),
                 lever * (np.sin(E) * E1 * np.cos(A) + np.cos(E) * np.sin(A) * A1),
                 lever * np.cos(E) * E1, -E1, 0.0, A1]
        assert np.allclose(d1[:6], hand1, rtol=1e-12, atol=1e-15), centre
        assert np.allclose(d2[3:6], [-E2, 0.0, A2], rtol=1e-12, atol=1e-15), centre
        checked += np.ptp(np.abs(hand1)) > 0
    assert checked >= 3                     # the base moved at most of the points


def test_what_has_no_derivative_answers_error_with_a_line(slew):
    """Order 2 of a rate (its jerk is not computed), order 3, order 0, an input or
    parameter, and a call before initialization: fmi3Error and a line naming it."""
    values, path = slew
    inst = fmi.Instance(path, "base")
    inst.md3 = fmi.unpack(path)[0]
    OPENED.append(inst)
    assert derivatives(inst, ["base_rate[1]"], 1)[0] == 3 and "not allowed in state Instantiated" in inst.log[-1]
    inst.initialize(0.0, values)
    inst.do_step(0.0, H)
    assert derivatives(inst, ["base_rate[1]"], 1)[0] == 0
    assert derivatives(inst, ["base_rate[1]"], 2)[0] == 3
    assert "base_rate[1] has no derivative of order 2 (it has 1)" in inst.log[-1]
    assert derivatives(inst, ["base_pose[1]"], 3)[0] == 3 and "maxOutputDerivativeOrder 2" in inst.log[-1]
    assert derivatives(inst, ["base_pose[1]"], 0)[0] == 3
    assert derivatives(inst, ["lever_arm"], 1)[0] == 3 and "is not an output" in inst.log[-1]
    status, axis = derivatives(inst, ["axis[1]", "axis[2]"], 2)
    assert status == 0 and np.array_equal(axis, [inst.get_real("axis_acc[1]"), inst.get_real("axis_acc[2]")])


# ------------------------------------------------------------------ the master's use
def slew_run(extrapolation, master_kind="jacobi", h=1e-3, stop=6.0, fmi_version=3):
    """The shipped slew to ``stop`` with the plant's base inputs recorded (every FMU FMI
    ``fmi_version``): (records, the telescope's parameter values)."""
    from studies import fmi3_derivatives as study
    scenario, paths, descriptions, values = runner.prepare(runner.resolve("telescope_slew"), fmi_version=fmi_version)
    scenario = dataclasses.replace(scenario, extrapolation=extrapolation, master=master_kind, step=h, stop_time=stop,
                                   record=study.RECORD, record_interval=0.02)
    values = runner.spec.bind(scenario, descriptions)
    result = runner.single.run(scenario, paths, values, None, "run")
    return result.records, values["base"]


def telescope_rows(base, t):
    params = dataclasses.replace(telescope.TelescopeParams.tianma(), lever_arm=base["lever_arm"])
    profile = telescope.motion_profile("slew", (base["start_azimuth"], base["start_elevation"]),
                                       (base["target_azimuth"], base["target_elevation"]),
                                       start_delay=base["start_delay"])
    return telescope.fmu_outputs(params, profile, t)


@pytest.mark.parametrize("master_kind", ["jacobi", "gauss-seidel"])
def test_the_master_feeds_the_taylor_mean_where_derivatives_exist(master_kind):
    """Jacobi: the plant's base_pose held over [t - h, t] is u + h/2 u' + h^2/6 u'' of the
    telescope at t - h (orders 1 and 2), base_rate u + h/2 u' (order 1 only), base_acc the
    linear extrapolation u + (u - u_prev)/2 (no derivative); u, u', u'' computed here by
    plant.telescope. Gauss-Seidel steps the telescope first: nothing is extrapolated."""
    h = 1e-3
    records, base = slew_run("derivatives", master_kind, h)
    t = records.time[records.time > base["start_delay"] + 0.1]
    now, before, earlier = (telescope_rows(base, t - d) for d in (0.0, h, 2 * h))
    fed = {name: np.column_stack([records[f"plant.{name}[{k}]"][np.isin(records.time, t)] for k in range(1, 7)])
           for name in ("base_pose", "base_rate", "base_acc")}
    if master_kind == "gauss-seidel":
        expected = {"base_pose": now[:, 0:6], "base_rate": now[:, 6:12], "base_acc": now[:, 12:18]}
    else:
        expected = {"base_pose": before[:, 0:6] + (0.5 * h * before[:, 6:12] + h * h / 6.0 * before[:, 12:18]),
                    "base_rate": before[:, 6:12] + 0.5 * h * before[:, 12:18],
                    "base_acc": before[:, 12:18] + 0.5 * (before[:, 12:18] - earlier[:, 12:18])}
    for name in fed:
        scale = np.max(np.abs(expected[name]), axis=0) + 1e-300
        assert np.max(np.abs(fed[name] - expected[name]) / scale) < 1e-11, name
    assert np.ptp(fed["base_pose"][:, 1]) > 1e-3           # the base moves


def test_derivatives_make_the_base_coupling_exact_to_third_order():
    """The plant's held base_pose against its exact mean over the step (Gauss-Legendre of
    plant.telescope.model's outputs): linear extrapolation errs by O(h^2) (39 nm at 1 ms, 25 m
    lever arm), the Taylor mean by O(h^3) (1e-4 nm); base_acc, without derivatives, is
    fed alike by both."""
    from studies import fmi3_derivatives as study
    errors = {}
    for extrapolation in ("linear", "derivatives"):
        records, base = slew_run(extrapolation)
        errors[extrapolation] = study.input_errors(records, 1e-3, base)
    linear, taylor = errors["linear"]["base_pose"][0], errors["derivatives"]["base_pose"][0]
    assert linear > 10.0 and taylor < linear * 1e-4
    assert errors["derivatives"]["base_rate"][0] < 0.5 * errors["linear"]["base_rate"][0]
    assert errors["derivatives"]["base_acc"] == errors["linear"]["base_acc"]


def test_extrapolation_derivatives_needs_a_source_that_gives_them(tmp_path):
    """With every FMU FMI 2 no connection starts at an FMU that gives derivatives: the
    scenario is refused naming the key and the remedy; the telescope alone as FMI 3 is
    enough."""
    text = (runner.SHIPPED / "telescope_slew.toml").read_text().replace('extrapolation = "linear"',
                                                                        'extrapolation = "derivatives"')
    scene = tmp_path / "scene.toml"
    scene.write_text(text)
    with pytest.raises(runner.spec.ScenarioError, match=r"extrapolation: .*set fmi_version = 3 on the telescope"):
        runner.prepare(scene)
    scene.write_text(text.replace("[fmus.base]", "[fmus.base]\nfmi_version = 3"))
    assert runner.prepare(scene)[0].extrapolation == "derivatives"
    # --implementation python with fmi_version = 3 already set: told to set it (the cause is the
    # pythonfmu telescope, FMI 2.0); now told so
    with pytest.raises(
        runner.spec.ScenarioError,
        match=r"extrapolation: .*the telescope instance is the pythonfmu "
        r"FMU \(implementation python.*run it native with fmi_",
    ) as told:
        runner.prepare(scene, implementation="python")
    assert "set fmi_version = 3" not in str(told.value)


def test_a_step_beyond_the_limit_is_refused_with_derivatives_as_with_linear(tmp_path):
    """The leg loop's signals have no derivatives: "derivatives" has the predicted limit of
    "linear" (2 ms on the slew; a 4 ms run diverges under both, studies.fmi3_derivatives),
    and the refusal names the scenario's extrapolation and what the loop gets."""
    text = (runner.SHIPPED / "telescope_slew.toml").read_text().replace('step = "1 ms"', 'step = "5 ms"')
    text = text.replace("[fmus.base]", "[fmus.base]\nfmi_version = 3")
    limits = {}
    for extrapolation in ("linear", "derivatives"):
        scene = tmp_path / f"{extrapolation}.toml"
        scene.write_text(text.replace('extrapolation = "linear"', f'extrapolation = "{extrapolation}"'))
        with pytest.raises(runner.spec.ScenarioError, match="beyond the predicted stability limit") as refused:
            runner.run_scenario(scene, tmp_path / "out", ci=True, progress=False)
        limits[extrapolation] = str(refused.value).split("stability limit ", 1)[1].split(" ", 2)[:2]
    assert limits["linear"] == limits["derivatives"]
    assert "extrapolation derivatives (linear on the leg loop" in str(refused.value)

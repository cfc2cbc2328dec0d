"""A model that is wrong (issue 30): the plant's payload against what the controller knows,
the leg encoders' scale and the base IMU's alignment, each against an independent truth,
in the pythonfmu FMU and its native twin alike."""
import numpy as np
import pytest

from plant.hexapod import model
from plant.rotations import rpy_matrix
from tests.fmu_helpers import open_fmu, reals, step

PAPER = model.StewartParams.paper()
POSE = [f"pose[{i}]" for i in range(1, 7)]
RATE = [f"pose_rate[{i}]" for i in range(1, 7)]


@pytest.fixture(scope="module")
def both(fmus, native):
    """{implementation: {script: FMU path}}: the session's FMUs (tests/conftest.py)."""
    return {"python": fmus, "native": native}


def _plant(path, dm, di, forces, dc=np.zeros(3)):
    values = {"moving_base": 0, "max_step": 1e-5, "payload_mass_error": dm,
              **{f"payload_inertia_error[{k + 1}]": di[k] for k in range(3)},
              **{f"payload_com_error[{k + 1}]": dc[k] for k in range(3)},
              **{f"leg_force[{k + 1}]": forces[k] for k in range(6)}}
    return open_fmu(path, **values)


@pytest.mark.parametrize("implementation", ["python", "native"])
def test_payload_error_changes_the_forces_by_the_statics_of_the_wrong_mass(both, implementation):
    """At rest at home, forces for the acceleration a computed with the paper's payload plus
    J^-T of the wrench the payload error adds, dm (a - g) and dI alpha (numpy, no kernel),
    start the plant with the payload errors at exactly a; the paper's forces do not."""
    dm, di = 180.0, np.array([300.0, -250.0, 400.0])
    acc = np.array([0.0, 0.0, 0.02, 0.01, -0.015, 0.005])
    nominal = model.inverse_dynamics(PAPER, model.HOME_POSE, np.zeros(6), acc)
    wrench = np.r_[dm * (acc[:3] + [0.0, 0.0, PAPER.gravity]), di * acc[3:]]
    corrected = nominal + np.linalg.solve(model.jacobian(PAPER, model.HOME_POSE).T, wrench)
    h = 1e-4
    got = {}
    for name, forces in (("corrected", corrected), ("nominal", nominal)):
        inst = _plant(both[implementation]["hexapod_plant_fmu"], dm, di, forces)
        assert step(inst, 0.0, h) == 0
        got[name] = reals(inst, RATE) / h       # the mean acceleration over h
    assert np.abs(got["corrected"] - acc).max() < 1e-3 * np.abs(acc).max()
    assert np.abs(got["nominal"] - acc).max() > 0.05 * np.abs(acc).max()    # the check can fail


@pytest.mark.parametrize("implementation", ["python", "native"])
def test_payload_com_error_needs_the_moment_of_its_weight(both, implementation):
    """At rest at home with the payload's centre of mass at c off o_P, the paper's holding
    forces plus J^-T of the offset weight's moment, (0, m g x R c) (numpy statics, no kernel),
    hold the platform still; the paper's forces alone tip it."""
    dc = np.array([0.03, -0.02, 0.1])
    nominal = model.inverse_dynamics(PAPER, model.HOME_POSE, np.zeros(6), np.zeros(6))
    moment = np.cross(PAPER.platform_mass * np.array([0.0, 0.0, -PAPER.gravity]),
                      rpy_matrix(model.HOME_POSE[3:]) @ dc)
    corrected = nominal + np.linalg.solve(model.jacobian(PAPER, model.HOME_POSE).T, np.r_[np.zeros(3), moment])
    h = 1e-4
    got = {}
    for name, forces in (("corrected", corrected), ("nominal", nominal)):
        inst = _plant(both[implementation]["hexapod_plant_fmu"], 0.0, np.zeros(3), forces, dc)
        assert step(inst, 0.0, h) == 0
        got[name] = reals(inst, RATE) / h
    assert np.abs(got["nominal"]).max() > 1e-2     # the offset's moment tips the platform
    assert np.abs(got["corrected"]).max() < 1e-6 * np.abs(got["nominal"]).max()


def test_payload_error_twins_agree(both):
    """The native plant perturbs its copy of the kernel's constants as the Python one its
    StewartParams: the same motion to the bit's neighbourhood."""
    forces = model.inverse_dynamics(PAPER, model.HOME_POSE, np.zeros(6), np.zeros(6)) * 1.001
    runs = []
    for implementation in ("python", "native"):
        inst = _plant(both[implementation]["hexapod_plant_fmu"], -120.0, np.array([50.0, 60.0, -70.0]), forces,
                      np.array([0.02, -0.04, 0.15]))
        for k in range(20):
            assert step(inst, k * 1e-3, 1e-3) == 0
        runs.append(reals(inst, POSE + RATE))
    np.testing.assert_allclose(runs[0], runs[1], rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("implementation", ["python", "native"])
def test_encoder_scale_error_scales_the_travel_from_home(both, implementation):
    scale = np.array([1e-4, -2e-4, 3e-4, 0.0, 5e-4, -1e-3])
    travel = np.array([0.01, -0.02, 0.03, 0.04, -0.05, 0.06])
    true = PAPER.home_lengths + travel
    inst = open_fmu(both[implementation]["leg_sensor_fmu"], **{f"scale_error[{k + 1}]": scale[k] for k in range(6)},
                    **{f"leg_length[{k + 1}]": true[k] for k in range(6)})
    assert step(inst, 0.0, 1e-3) == 0
    measured = reals(inst, [f"measured_length[{k + 1}]" for k in range(6)])
    np.testing.assert_allclose(measured - PAPER.home_lengths, (1 + scale) * travel, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("implementation", ["python", "native"])
def test_imu_misalignment_rotates_the_measured_acceleration(both, implementation):
    """No noise, no bias: the estimate is R_WB R R_WB^T a for the base's a in {W}, with R
    the misalignment and R_WB = Rz(yaw) Rx(roll) (plant.rotations, not the C's matrices)."""
    angles = np.array([2e-3, -3e-3, 1.5e-3])
    pose = np.array([0.0, 0.0, 0.0, 0.4, 0.0, 1.1])
    acc = np.array([0.3, -0.2, 0.05])
    values = {"source": 1, "gyro_noise_density": 0.0, "gyro_bias": 0.0, "accel_noise_density": 0.0,
              "accel_bias": 0.0, **{f"imu_alignment[{k + 1}]": angles[k] for k in range(3)},
              **{f"true_base_pose[{k + 1}]": pose[k] for k in range(6)},
              **{f"true_base_acc[{k + 1}]": acc[k] for k in range(3)}}
    inst = open_fmu(both[implementation]["base_sensor_fmu"], **values)
    assert step(inst, 0.0, 1e-3) == 0
    measured = reals(inst, [f"base_acc[{k + 1}]" for k in range(3)])
    world = rpy_matrix([pose[3], 0.0, pose[5]])
    expected = world @ rpy_matrix(angles) @ world.T @ acc
    np.testing.assert_allclose(measured, expected, rtol=0, atol=1e-14)
    assert np.abs(measured - acc).max() > 1e-4     # the misalignment shows


@pytest.mark.parametrize("implementation", ["python", "native"])
@pytest.mark.parametrize("di", [[-1841.0, -1841.0, 3237.0], [0.0, 0.0, 893.0]])
def test_a_payload_no_rigid_body_has_is_refused_at_initialization(both, implementation, di):
    """The issue's body (Izz 9711 > Ixx + Iyy 3684) and Izz 1 kg.m2 over Ixx + Iyy = 7366 (6474 +
    893): each refused through FMI status, the message saying why; +892 (Izz = Ixx + Iyy exactly,
    a thin plate) is a body, and initialises (the moments' +-50 % ranges keep them > 0)."""
    from scenarios.cosim.fmi import FmuError
    path = both[implementation]["hexapod_plant_fmu"]
    with pytest.raises(FmuError, match="no rigid body"):
        _plant(path, 0.0, di, np.zeros(6))
    _plant(path, 0.0, [0.0, 0.0, 892.0], np.zeros(6))   # Izz = 7366 = Ixx + Iyy: a thin plate, admissible

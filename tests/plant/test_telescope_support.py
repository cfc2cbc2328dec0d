"""The flexible feed support (plant/c/telescope.h mb_tel_support) against the analytic response
of a damped linear mode: frequency and damping identified from a free decay, amplitude and
phase of the steady response to a harmonic load against |H(jw)| and arg H(jw), the static
deflection under a wrench and under the rigid base's acceleration against the generalized
force worked by hand, the exactness of the step (one long step = many short ones), and on a
turning base the reported sway rate and acceleration against the derivatives of its position."""
import numpy as np
import pytest

from plant.errors import InvalidInputError
from plant.telescope import model as telescope

F, ZETA, MASS = 1.8, 0.015, 1e4
W = 2 * np.pi * F
SHAPE = np.array([1.0, 0.0, 0.0, 0.0, 0.06, 0.0])
ROLL, YAW = np.radians(60.0), np.radians(-150.0)   # a base pointing at E = 30 deg, A = -150 deg


def modes(frequency=(F, 0.0), damping=(ZETA, ZETA), mass=(MASS, MASS), participation=(1.0, 1.0),
          shapes=(SHAPE, np.zeros(6)), **kw):
    return telescope.support(frequency, damping, mass, participation, np.array(shapes), **kw)


def rigid_row(acc_B=(0.0, 0.0, 0.0)):
    """A telescope row (60) of a base at rest at (ROLL, YAW) whose origin accelerates by acc_B in {B}."""
    row = np.zeros(60)
    row[3], row[5] = ROLL, YAW
    cr, sr, cy, sy = np.cos(ROLL), np.sin(ROLL), np.cos(YAW), np.sin(YAW)
    R = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]]) @ np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    row[12:15] = R @ np.asarray(acc_B)
    return row


def run(support, loads, h, acc_B=(0.0, 0.0, 0.0)):
    """Sway (n + 1, 6) and the rows (n + 1, 60): the start, then one step of h per load (6)."""
    state, sway, load = np.zeros(6), np.zeros(6), np.ascontiguousarray(loads[0], dtype=float)
    row = rigid_row(acc_B)
    telescope.support_advance(support, None, load, state, row, sway)
    sways, rows = [sway.copy()], [row.copy()]
    for w in loads:
        load[:] = w
        row = rigid_row(acc_B)
        telescope.support_advance(support, h, load, state, row, sway)
        sways.append(sway.copy())
        rows.append(row)
    return np.array(sways), np.array(rows)


def test_free_decay_gives_the_frequency_and_damping():
    """Released from the static deflection under a preload: the decay's samples obey
    x[k+1] = 2 e^{-zeta w h} cos(w_d h) x[k] - e^{-2 zeta w h} x[k-1] (the exact recurrence
    of a sampled damped oscillation), fitted by least squares; and the log decrement of the
    peaks over 20 periods. Both give the parameters back."""
    h, preload = 1e-3, np.array([5e3, 0, 0, 0, 0, 0])
    x = run(modes(preload=preload), np.zeros((12000, 6)), h)[0][:, 0]
    assert x[0] == pytest.approx(5e3 / (MASS * W ** 2), rel=1e-12)   # starts in equilibrium under it
    (a1, a2), *_ = np.linalg.lstsq(np.column_stack([x[1:-1], x[:-2]]), x[2:], rcond=None)
    r = np.sqrt(-a2)
    wd = np.arccos(a1 / (2 * r)) / h
    sigma = -np.log(r) / h
    assert np.hypot(sigma, wd) / (2 * np.pi) == pytest.approx(F, rel=1e-9)
    assert sigma / np.hypot(sigma, wd) == pytest.approx(ZETA, rel=1e-7)
    peaks = [k for k in range(1, x.size - 1) if x[k - 1] < x[k] >= x[k + 1] and x[k] > 0]
    delta = np.log(x[peaks[0]] / x[peaks[20]]) / 20
    assert delta / np.sqrt(4 * np.pi ** 2 + delta ** 2) == pytest.approx(ZETA, rel=2e-3)
    assert 20 / ((peaks[20] - peaks[0]) * h) == pytest.approx(F * np.sqrt(1 - ZETA ** 2), rel=2e-3)


@pytest.mark.parametrize("ratio", [0.5, 1.0, 2.0])
def test_steady_harmonic_response_is_the_transfer_function(ratio):
    """A force F0 sin(Wt) on the tip, held over each 4 ms step as a master holds it (a delay
    of h / 2 and a gain sinc(W h / 2)): the steady sway's amplitude and phase, fitted at W
    after the transient (26 s: 15 decay times at 5 % damping), equal |H| and arg H of
    H = (1 / m) / (w^2 - W^2 + 2 j zeta w W), at, below and above resonance."""
    h, f0, omega, zeta = 4e-3, 2e3, ratio * W, 0.05
    t = np.arange(7500) * h
    loads = np.zeros((t.size, 6))
    loads[:, 0] = f0 * np.sin(omega * t)
    x = run(modes(damping=(zeta, zeta)), loads, h)[0][1:, 0]
    end = t + h
    keep = end > 26.0
    basis = np.column_stack([np.sin(omega * end[keep]), np.cos(omega * end[keep])])
    (s, c), *_ = np.linalg.lstsq(basis, x[keep], rcond=None)
    H = (1 / MASS) / (W ** 2 - omega ** 2 + 2j * zeta * W * omega)
    hold = np.sinc(omega * h / 2 / np.pi) * np.exp(-1j * omega * h / 2)
    expected = f0 * H * hold
    assert np.hypot(s, c) == pytest.approx(abs(expected), rel=1e-4)
    assert np.arctan2(c, s) == pytest.approx(np.angle(expected), abs=1e-4)


def test_static_deflection_under_a_wrench_and_an_acceleration():
    """Held long enough (a step of 200 s: the exact discretisation takes any step), the sway is
    the static deflection: the generalized force load_gain (shape_t . F + shape_r . (M + r x F))
    worked by hand, and -participation shape_t . a_B for a base accelerating at a_B (in {B});
    the tilt is the shape's rotation times the translation."""
    load = np.array([300.0, -200.0, 1000.0, 50.0, 400.0, 0.0])
    point = np.array([0.1, 0.0, -2.6815])
    moment = load[3:] + np.cross(point, load[:3])
    by_hand = 1.25 * (SHAPE[:3] @ load[:3] + SHAPE[3:] @ moment) / (MASS * W ** 2)
    sway = run(modes(load_gain=1.25, load_point=point), [load], 200.0)[0][-1]
    assert sway[0] == pytest.approx(by_hand, rel=1e-9)
    assert sway[4] == pytest.approx(0.06 * by_hand, rel=1e-9)
    acc = (0.09, -0.05, 0.3)
    sway = run(modes(participation=(1.3, 1.0)), [np.zeros(6)], 200.0, acc)[0][-1]
    assert sway[0] == pytest.approx(-1.3 * 0.09 / W ** 2, rel=1e-9)


def test_one_long_step_equals_many_short_ones():
    """The step is the mode's exact discretisation (constant load over the step): 1 step of
    0.1 s equals 100 of 1 ms, to rounding."""
    load = np.array([1e3, 0, 0, 0, 0, 0])
    long = run(modes(), [load], 0.1)[0][-1]
    short = run(modes(), [load] * 100, 1e-3)[0][-1]
    assert long[0] == pytest.approx(short[0], rel=1e-12)


def test_rigid_by_default_and_bad_settings_are_named():
    """Frequencies 0: no mode is on (the FMU then leaves every row as it was). A negative
    frequency, a damping of 1 or more, a modal mass of 0 or a NaN are refused by name."""
    assert not telescope.support_on(modes(frequency=(0.0, 0.0)))
    assert telescope.support_on(modes(frequency=(0.0, 2.0)))
    for bad in (dict(frequency=(-1.0, 0.0)), dict(damping=(1.0, 0.0)), dict(mass=(0.0, 1.0)),
                dict(participation=(np.nan, 1.0))):
        with pytest.raises(InvalidInputError, match="support mode needs"):
            modes(**bad)
    state, sway, row = np.zeros(6), np.zeros(6), rigid_row()
    with pytest.raises(InvalidInputError, match="support_load input contains NaN"):
        telescope.support_advance(modes(), 1e-3, np.array([np.nan, 0, 0, 0, 0, 0]), state, row, sway)
    assert not state.any()


def test_the_sway_s_rate_and_acceleration_are_its_position_s_derivatives_on_a_turning_base():
    """On a base that turns (roll and yaw with rates and accelerations, as in a slew), the sway
    added to the row's position, rate and acceleration is one displacement carried by the
    turning frame: the rate and acceleration the support reports are the time derivatives of
    the position it reports, taken here by central differences (error ~h^2 jerk/6, 1e-9 m/s2).
    The check is kinematic and exact for any motion: it pins the transport terms, w x d', the
    centripetal w x (w x d) and the Coriolis 2 w x d' (without its factor 2 the acceleration
    is off by up to 3.0e-3 m/s2 here, 15,000x the tolerance: tried)."""
    r1, r2, y1, y2 = 0.3, 0.2, -0.4, 0.1        # rad/s, rad/s2: roll and yaw rates and accelerations
    h, steps = 1e-4, 2000

    def rigid(t):
        row = np.zeros(60)
        row[3], row[9], row[15] = ROLL + r1 * t + r2 * t * t / 2, r1 + r2 * t, r2
        row[5], row[11], row[17] = YAW + y1 * t + y2 * t * t / 2, y1 + y2 * t, y2
        return row      # the base's origin at rest: what is left in row[0:15:6] is the sway's own

    support, load = modes(), np.array([1e3, 0.0, 0.0, 0.0, 0.0, 0.0])    # the mode swings from rest
    state, sway, rows = np.zeros(6), np.zeros(6), []
    row = rigid(0.0)
    telescope.support_advance(support, None, load, state, row, sway)
    rows.append(row)
    for k in range(1, steps + 1):
        row = rigid(k * h)
        telescope.support_advance(support, h, load, state, row, sway)
        rows.append(row)
    rows = np.array(rows)
    position, rate, acc = rows[:, 0:3], rows[:, 6:9], rows[:, 12:15]
    assert np.abs(position).max() > 1e-4                       # it swings: ~qs = 0.78 mm
    np.testing.assert_allclose((position[2:] - position[:-2]) / (2 * h), rate[1:-1], rtol=0, atol=1e-8)
    np.testing.assert_allclose((rate[2:] - rate[:-2]) / (2 * h), acc[1:-1], rtol=0, atol=2e-7)
    # the Coriolis term's size at the largest sway rate: the tolerance is far below half of it
    k = np.argmax(np.linalg.norm(rate, axis=1))
    w_world = np.array([rows[k, 9] * np.cos(rows[k, 5]), rows[k, 9] * np.sin(rows[k, 5]), rows[k, 11]])
    assert np.linalg.norm(np.cross(w_world, rate[k])) > 1e3 * 2e-7

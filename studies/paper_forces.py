"""The paper's two scenarios (Yao et al. 2018, Fig. 4-6): leg forces along the 6 s
quintic to the S-band pose with the base fixed and with the base turning (roll 0 -> 45
deg, yaw 0 -> 30 deg), and their difference. Tension is plotted positive, as the paper
does (our F is positive when it extends the leg).

Two readings of the moving-base equations, an option of this comparison only (the plant
stays right):

* ``model``: eqs. 39-40 as derived, gravity once, turned into {B} (R^T g_B), with the
  base's inertial terms: what plant.hexapod.model computes.
* ``eq43``: eq. 43 as printed. It subtracts both m g_B v* (the fixed-base gravity of
  eq. 37) and m (R^T g_B) v* (eq. 39's turned gravity), so gravity acts twice, and it has
  none of eq. 40's base inertial terms F_{.|B}, M_{.|B}. Evaluated exactly: inverse
  dynamics is linear in g, so the extra term is the fixed-base gravity load
  F(g) - F(g = 0) added to the base_gravity fidelity (gravity turned, no base inertia).
"""
import dataclasses
import pathlib

import numpy as np
from matplotlib.figure import Figure

from plant.hexapod.model import HOME_POSE, S_BAND_POSE, StewartParams, inverse_dynamics
from plant.trajectory import quintic
from scenarios.output.charts import save

DURATION = 6.0
BASE_END = np.array([0.0, 0.0, 0.0, np.radians(45.0), 0.0, np.radians(30.0)])
READINGS = {"model": "our model (eqs. 39-40: gravity once, base inertia kept)",
            "eq43": "the paper's eq. 43 as printed (gravity twice, no base inertia)"}
# Legs that the layout makes nearly equal come in pairs, one colour a pair: the first a
# wide pale line, the second a thin dashed one on top, so a pair that coincides shows both.
LEG_STYLES = [{"color": "C0", "lw": 4.0, "alpha": 0.4}, {"color": "C0", "lw": 1.3, "ls": (0, (4, 2))},
              {"color": "C3", "lw": 4.0, "alpha": 0.4}, {"color": "C2", "lw": 4.0, "alpha": 0.4},
              {"color": "C2", "lw": 1.3, "ls": (0, (4, 2))}, {"color": "C3", "lw": 1.3, "ls": (0, (4, 2))}]


def paper_leg_forces(n=601, params=None, reading="model"):
    """Time (n,) and leg forces (n, 6) [N] with the base fixed (eq. 37) and moving, the
    latter in the given reading (READINGS)."""
    if reading not in READINGS:
        raise ValueError(f"unknown reading {reading!r}; choose one of {list(READINGS)}")
    params = params or StewartParams.paper()
    t = np.linspace(0.0, DURATION, n)
    pose = quintic(HOME_POSE, S_BAND_POSE, DURATION, t)
    base = quintic(np.zeros(6), BASE_END, DURATION, t)
    fixed = inverse_dynamics(params, *pose)
    if reading == "model":
        moving = inverse_dynamics(params, *pose, *base)
    else:
        weightless = dataclasses.replace(params, gravity=0.0)
        fixed_gravity = fixed - inverse_dynamics(weightless, *pose)   # m g_B v* terms of eq. 37
        moving = inverse_dynamics(params, *pose, *base, fidelity="base_gravity") + fixed_gravity
    return t, fixed, moving


def change_summary(fixed, moving):
    """Per leg, tension positive [kN]: largest rise and largest fall of moving - fixed,
    and the force at the end of the moving case."""
    diff = -(moving - fixed) / 1e3
    return {"rise": diff.max(axis=0), "fall": diff.min(axis=0), "end": -moving[-1] / 1e3,
            "start": -moving[0] / 1e3}


def _legs(ax, t, forces):
    for leg in range(6):
        ax.plot(t, -forces[:, leg] / 1e3, label=f"leg {leg + 1}", **LEG_STYLES[leg])
    ax.grid(True, alpha=0.3)


def plot_paper_forces(t, fixed, moving, path):
    """Fig. 4-6 of the paper: the base-fixed forces once, on their own scale (they stay
    within 0.3 kN of the 5.2 kN static load and are the same in every reading), then one
    column per reading (``moving``: {reading: forces}) with the base moving and moving -
    fixed on one shared scale; tension (-F) positive, kN, one legend. Returns the fixed
    panel and the (2, readings) array of the others (the figure is closed)."""
    fig = Figure(figsize=(5.2 * len(moving) + 0.8, 8.6), layout="constrained")
    grid = fig.add_gridspec(3, len(moving), height_ratios=(0.8, 1, 1))
    top = fig.add_subplot(grid[0, :])
    _legs(top, t, fixed)
    top.set_title("base fixed (eq. 37): the same in both readings; own scale, zoomed on the 5.2 kN static load",
                  fontsize=9.5)
    top.set_ylabel("tension + [kN]")
    axes = np.empty((2, len(moving)), dtype=object)
    for col, (reading, forces) in enumerate(moving.items()):
        for row, (data, title) in enumerate(((forces, "base moving: roll 0->45 deg, yaw 0->30 deg"),
                                             (forces - fixed, "moving - fixed"))):
            ax = axes[row, col] = fig.add_subplot(grid[row + 1, col], sharex=top,
                                                  sharey=axes[0, 0] if axes[0, 0] is not None else None)
            _legs(ax, t, data)
            ax.axhline(0.0, color="0.4", lw=0.6)
            ax.set_title(f"{READINGS[reading]}\n{title}" if row == 0 else title, fontsize=9.5)
        axes[1, col].set_xlabel("time [s]")
    for ax in axes[:, 0]:
        ax.set_ylabel("leg force, tension + [kN]")
    fig.legend(*top.get_legend_handles_labels(), loc="outside lower center", ncol=6, fontsize=9,
               title="legs (pairs the layout makes nearly equal: one colour, wide pale / thin dashed)")
    fig.suptitle("Paper scenarios (Yao et al. 2018, Fig. 4-6): leg forces; base moving and the difference on one "
                 "force scale", fontsize=11)
    save(fig, path)
    return top, axes


def main(outdir="out/paper"):
    outdir = pathlib.Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    moving = {}
    for reading in READINGS:
        t, fixed, moving[reading] = paper_leg_forces(reading=reading)
    path = outdir / "leg_forces.png"
    plot_paper_forces(t, fixed, moving, path)
    print(f"paper scenarios: chart {path}")
    for reading, forces in moving.items():
        s = change_summary(fixed, forces)
        print(f"  {READINGS[reading]}: moving - fixed per leg, tension + [kN]")
        print("    largest rise: " + ", ".join(f"{v:.2f}" for v in s["rise"]))
        print("    largest fall: " + ", ".join(f"{v:.2f}" for v in s["fall"]))
    return path


if __name__ == "__main__":
    main()

"""The paper's two scenarios (Yao et al. 2018, Fig. 4-6): leg forces along the 6 s
quintic to the S-band pose with the base fixed and with the base turning (roll 0 -> 45
deg, yaw 0 -> 30 deg), and their difference. Tension is plotted positive, as the paper
does (our F is positive when it extends the leg).

Two readings of the moving-base equations, an option of this comparison only (the plant
stays right):

* ``model``: eqs. 39-40 as derived, gravity once, turned into {B} (R^T g_B), with the
  base's inertial terms: what plant.stewart computes.
* ``eq43``: eq. 43 as printed. It subtracts both m g_B v* (the fixed-base gravity of
  eq. 37) and m (R^T g_B) v* (eq. 39's turned gravity), so gravity acts twice, and it has
  none of eq. 40's base inertial terms F_{.|B}, M_{.|B}. Evaluated exactly: inverse
  dynamics is linear in g, so the extra term is the fixed-base gravity load
  F(g) - F(g = 0) added to the base_gravity fidelity (gravity turned, no base inertia).
"""
import dataclasses
import pathlib

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from movingbase.plant.stewart import HOME_POSE, S_BAND_POSE, StewartParams, inverse_dynamics
from movingbase.plant.trajectory import quintic

DURATION = 6.0
BASE_END = np.array([0.0, 0.0, 0.0, np.radians(45.0), 0.0, np.radians(30.0)])
READINGS = {"model": "our model (eqs. 39-40: gravity once, base inertia kept)",
            "eq43": "the paper's eq. 43 as printed (gravity twice, no base inertia)"}
# legs that the layout makes nearly equal come in pairs: same colour family, solid / dashed
LEG_STYLES = [("C0", "-"), ("C0", "--"), ("C3", "-"), ("C2", "-"), ("C2", "--"), ("C3", "--")]


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


def plot_paper_forces(t, cases, path):
    """Fig. 4-6 of the paper, one column per reading: base fixed, base moving, moving -
    fixed; tension (-F) positive, kN, one force scale for all panels, one legend.
    ``cases``: {reading: (fixed, moving)}. Returns the axes array (the figure is closed)."""
    fig, axes = plt.subplots(3, len(cases), figsize=(5.5 * len(cases) + 1, 9), sharex=True, sharey=True,
                             squeeze=False, layout="constrained")
    for col, (reading, (fixed, moving)) in enumerate(cases.items()):
        titles = ("base fixed (eq. 37)", "base moving: roll 0->45 deg, yaw 0->30 deg", "moving - fixed")
        for row, (forces, title) in enumerate(zip((fixed, moving, moving - fixed), titles)):
            ax = axes[row, col]
            for leg in range(6):
                color, ls = LEG_STYLES[leg]
                ax.plot(t, -forces[:, leg] / 1e3, color=color, ls=ls, lw=1.4, label=f"leg {leg + 1}")
            ax.axhline(0.0, color="0.4", lw=0.6)
            ax.set_title(title if col == 0 and row else (f"{READINGS[reading]}\n{title}" if row == 0 else title),
                         fontsize=9.5)
            ax.grid(True, alpha=0.3)
        for row in range(3):
            axes[row, 0].set_ylabel("leg force, tension + [kN]")
        axes[-1, col].set_xlabel("time [s]")
    fig.legend(*axes[0, 0].get_legend_handles_labels(), loc="outside lower center", ncol=6,
               title="legs (pairs the layout makes nearly equal: one colour, solid / dashed)", fontsize=9)
    fig.suptitle("Paper scenarios (Yao et al. 2018, Fig. 4-6): leg forces, one force scale for every panel")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return axes


def main(outdir="out/paper"):
    outdir = pathlib.Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    cases = {}
    for reading in READINGS:
        t, fixed, moving = paper_leg_forces(reading=reading)
        cases[reading] = (fixed, moving)
    path = outdir / "leg_forces.png"
    plot_paper_forces(t, cases, path)
    print(f"paper scenarios: chart {path}")
    for reading, (fixed, moving) in cases.items():
        s = change_summary(fixed, moving)
        print(f"  {READINGS[reading]}: moving - fixed per leg, tension + [kN]")
        print("    largest rise: " + ", ".join(f"{v:.2f}" for v in s["rise"]))
        print("    largest fall: " + ", ".join(f"{v:.2f}" for v in s["fall"]))
    return path


if __name__ == "__main__":
    main()

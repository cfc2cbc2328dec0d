"""The paper's two scenarios (Yao et al. 2018, Fig. 4-6): leg forces along the 6 s
quintic to the S-band pose with the base fixed and with the base turning (roll 0 -> 45
deg, yaw 0 -> 30 deg), and their difference. Tension is plotted positive, as the paper
does (our F is positive when it extends the leg)."""
import pathlib

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from plant.stewart import HOME_POSE, S_BAND_POSE, StewartParams, inverse_dynamics
from plant.trajectory import quintic

DURATION = 6.0
BASE_END = np.array([0.0, 0.0, 0.0, np.radians(45.0), 0.0, np.radians(30.0)])


def paper_leg_forces(n=601, params=None):
    """Time (n,) and leg forces (n, 6) [N] with the base fixed and moving."""
    params = params or StewartParams.paper()
    t = np.linspace(0.0, DURATION, n)
    pose = quintic(HOME_POSE, S_BAND_POSE, DURATION, t)
    base = quintic(np.zeros(6), BASE_END, DURATION, t)
    fixed = inverse_dynamics(params, *pose)
    moving = inverse_dynamics(params, *pose, *base)
    return t, fixed, moving


def plot_paper_forces(t, fixed, moving, path):
    """Fig. 4-6 of the paper in one figure: tension (-F) positive, kN."""
    fig, axes = plt.subplots(3, 1, figsize=(8, 9), sharex=True)
    titles = ("base fixed", "base moving (roll 0->45 deg, yaw 0->30 deg)", "moving - fixed")
    for ax, forces, title in zip(axes, (fixed, moving, moving - fixed), titles):
        for leg in range(6):
            ax.plot(t, -forces[:, leg] / 1e3, label=f"leg {leg + 1}")
        ax.set_title(title)
        ax.set_ylabel("leg force, tension + [kN]")
        ax.grid(True, alpha=0.3)
    axes[0].legend(ncol=6, fontsize="small")
    axes[-1].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(outdir="out/paper"):
    outdir = pathlib.Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    t, fixed, moving = paper_leg_forces()
    path = outdir / "leg_forces.png"
    plot_paper_forces(t, fixed, moving, path)
    diff = np.abs(moving - fixed).max(axis=0)
    print(f"paper scenarios: chart {path}")
    print("  peak |moving - fixed| per leg [kN]: " + ", ".join(f"{d / 1e3:.2f}" for d in diff))
    return path


if __name__ == "__main__":
    main()

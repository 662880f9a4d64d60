"""Plots the radial deposit profile of a blob of coffee dried on a flat cloth, with the
Coffee preset's drying (the solute carried by the flow, a pinned edge, vapour-limited
evaporation: a tide line) and with the seed's drying (issue 13 §2), into
docs/tide-line-profile.png. The same case as rust/madder/tests/tide_lines.rs, on a square
grid: 0.3 kg/m² poured within 3 cm of the centre, steps of 0.1 s for the first 20 s
(while it spreads), then 4 s, until dry.

Run: PYTHONPATH=.venv/madder-wheel .venv/bin/python docs/tide_line_profile.py
(needs matplotlib: .venv/bin/pip install matplotlib)."""

import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import madder  # noqa: E402

COFFEE = dict(absorption=2.0, saturation=0.1, adsorption=0.05, capacity=2e-4, evaporation=5e-5,
              evaporation_boundary=1.5)
TIDE_LINES = dict(carry_solute=True, residual_saturation=0.1, vapour_limited=True)


def grid(n=121, half=0.1):
    x = np.linspace(-half, half, n)
    xx, yy = np.meshgrid(x, x)
    pos = np.stack([xx.ravel(), yy.ravel(), np.zeros(n * n)], axis=1)
    faces = []
    for i in range(n - 1):
        for j in range(n - 1):
            a, b, c, d = i * n + j, i * n + j + 1, (i + 1) * n + j + 1, (i + 1) * n + j
            faces += [[a, b, c], [a, c, d]] if (i + j) % 2 == 0 else [[a, b, d], [b, c, d]]
    return np.array(faces, dtype=np.uint32), pos


def dry(tide):
    faces, pos = grid()
    sim = madder.Simulator(faces, pos, pos, use_gravity=False, use_rectilinear=False,
                           use_coriolis=False, color=(0.25, 0.13, 0.05), **COFFEE,
                           **(TIDE_LINES if tide else {}))
    r = np.hypot(pos[:, 0], pos[:, 1])
    sim.add_liquid((r < 0.03).astype(np.float32) * 0.3, 0.012)
    s0 = sim.totals()["solute"]
    while sim.totals()["solvent"] > 1e-9:
        sim.step(pos, 0.1 if sim.time < 20.0 else 4.0)
    d = sim.densities()
    solute = d["solute"] + d["absorbed_solute"] + d["adsorbed"]
    print(f"tide lines {tide}: dry at {sim.time:.0f} s, solute defect "
          f"{abs(sim.totals()['solute'] - s0) / s0:.1e}")
    area = sim.vertex_area
    edges = np.arange(0.0, 0.1 + 1e-9, 0.002)
    k = np.digitize(r, edges) - 1
    mass = np.bincount(k, weights=solute * area, minlength=len(edges))
    cell = np.bincount(k, weights=area, minlength=len(edges))
    return 0.5 * (edges[1:] + edges[:-1]), (mass / np.maximum(cell, 1e-300))[: len(edges) - 1]


def main():
    fig, ax = plt.subplots(figsize=(7, 4), dpi=120)
    for tide, label in ((False, "seed's drying (rim cells × 1.5, solute diffusing)"),
                        (True, "tide lines: carried solute, pinned edge, vapour-limited rim")):
        r, d = dry(tide)
        ax.plot(1e3 * r, 1e3 * d, label=label, drawstyle="steps-mid")
    ax.set_xlabel("distance from the centre of the pour (mm)")
    ax.set_ylabel("dry solute density (g/m²)")
    ax.set_title("Coffee dried on a flat cloth (0.3 kg/m² poured within 3 cm)")
    ax.set_xlim(0, 80)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    out = pathlib.Path(__file__).with_name("tide-line-profile.png")
    fig.savefig(out)
    print("wrote", out)


if __name__ == "__main__":
    main()

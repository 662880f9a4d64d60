"""Plot the angle noise study (seed Fig. 3.3 / Fig. 3.6) into docs/angles-noise.png.

Runs the Rust test `angles_noise` (release) with MADDER_ANGLES_NOISE_CSV set, reads the CSV
it writes and plots, per mesh, the Procrustes RMS error over the bounding-box diagonal
against the noise level for the spectral method, the spectral method with descent, the
tracked reconstruction started from the spectral one and the sequential baseline. Needs
matplotlib (tests/requirements.txt):

    .venv/bin/python tests/bench/angles_noise.py [--csv FILE] [--out docs/angles-noise.png]

With --csv FILE and no cargo run, an existing CSV is plotted.
"""

import argparse
import csv
import os
import pathlib
import subprocess
import tempfile

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]


def run_study(path: str) -> None:
    env = dict(os.environ, MADDER_ANGLES_NOISE_CSV=path)
    subprocess.run(
        ["cargo", "test", "--release", "-p", "madder", "--test", "angles_noise", "--", "--nocapture"],
        cwd=ROOT,
        env=env,
        check=True,
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--csv", help="plot this CSV instead of running the study")
    ap.add_argument("--out", default=str(ROOT / "docs" / "angles-noise.png"))
    args = ap.parse_args()
    path = args.csv
    if path is None:
        path = os.path.join(tempfile.mkdtemp(), "angles-noise.csv")
        run_study(path)
    rows = list(csv.DictReader(open(path)))
    meshes = list(dict.fromkeys(r["mesh"] for r in rows))
    fig, axes = plt.subplots(1, len(meshes), figsize=(3.2 * len(meshes), 3.4), squeeze=False)
    styles = [
        ("spectral", "spectral + voting", "C0", "o-"),
        ("spectral_descent", "+ 30 descent steps", "C2", "s--"),
        ("tracked", "tracked (from the spectral fit)", "C1", "d:"),
        ("sequential", "sequential (baseline)", "C3", "^-"),
    ]
    for ax, m in zip(axes[0], meshes, strict=True):
        rs = [r for r in rows if r["mesh"] == m]
        levels = [float(r["level_pct"]) for r in rs]
        for key, label, color, style in styles:
            ax.semilogy(levels, [float(r[key]) for r in rs], style, color=color, label=label)
        closed = m not in ("sheet", "flag")
        what = "dihedral noise" if closed else "noise on all angles"
        ax.set_title(f"{m} ({'closed' if closed else 'open'})")
        ax.set_xlabel(f"± % {what}")
        ax.set_xticks(levels)
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].set_ylabel("Procrustes RMS error / bbox diagonal")
    axes[0][0].legend(fontsize=7)
    fig.suptitle("Surfaces from angles: reconstruction error under uniform angle noise (3 trials)")
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()

"""The angle codec against position coding, on the flag and tablecloth fixtures' cloth
motion (frames exported from the .blend files by export_cloth_frames.py, in the venv's
bpy). Prints bits per vertex per frame against the maximum and RMS error over the
bounding-box diagonal for the angle codec over several quantization levels, and the
baselines of the same run: raw float32 (96), raw 16-bit positions (48), positions with
temporal prediction and the same range coder; draws docs/codec-curve.png with Dynapack's
published anchors.

    PYTHONPATH=.venv/madder-wheel .venv/bin/python tests/bench/bench_codec.py [--quick]
"""

import argparse
import os
import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np

import madder

ROOT = pathlib.Path(__file__).resolve().parents[2]
FRAMES = ROOT / "target" / "codec-frames"
# Dynapack (Ibarria & Rossignac 2003): bits/vertex/frame, worst error / bounding box
DYNAPACK = [(7, 4.1, 3e-3), (11, 7.1, 2.4e-4), (13, 8.7, None)]


def load(key):
    path = FRAMES / f"{key}.npz"
    if not path.exists():
        script = ROOT / "tests" / "bench" / "export_cloth_frames.py"
        subprocess.run([sys.executable, str(script), str(FRAMES)], check=True)
    z = np.load(path)
    return z["faces"], z["frames"]


def angle_codec(faces, frames, bits, corners="every"):
    with tempfile.TemporaryDirectory() as d:
        enc = madder.MotionEncoder(os.path.join(d, "m.madm"), faces, bits=bits, corners=corners)
        t = time.perf_counter()
        for x in frames:
            enc.add_frame(x)
        s = enc.finish()
        s["seconds"] = time.perf_counter() - t
        t = time.perf_counter()
        r = madder.MotionCodec(os.path.join(d, "m.madm"))
        for k in range(len(r)):
            r.read_frame(k)
        s["decode_seconds"] = time.perf_counter() - t
    return s


def rolled_sheet(n=316, frames=20):
    """A 100k-vertex sheet rolled about a turning axis, its curvature breathing, with a
    ripple: (faces, frames) at 25 frames a second."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    u, v = i.ravel() / (n - 1), j.ravel() / (n - 1)
    a = (i[:-1, :-1] * n + j[:-1, :-1]).ravel()
    b, c, d = a + n, a + n + 1, a + 1
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.uint32)
    out = []
    for k in range(frames):
        t = k / 25
        curv = 1.5 + 0.5 * np.sin(2 * t)
        ang = curv * (u - 0.5)
        x = np.sin(ang) / curv
        z = (1 - np.cos(ang)) / curv + 0.01 * np.sin(6 * v + 3 * t)
        y = v - 0.5
        th = 0.4 * t
        out.append(np.stack([x * np.cos(th) - y * np.sin(th), x * np.sin(th) + y * np.cos(th), z], 1))
    return faces, np.stack(out)


def decode_100k():
    """Issue 15's decode target as a user meets it: frames of a 100k-vertex cloth read in
    order through madder.MotionCodec.read_frame (keyframe interval 16, 12 bits)."""
    faces, frames = rolled_sheet()
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "sheet.madm")
        t = time.perf_counter()
        enc = madder.MotionEncoder(path, faces, bits=12)
        for x in frames:
            enc.add_frame(x)
        s = enc.finish()
        t_enc = time.perf_counter() - t
        r = madder.MotionCodec(path)
        ms = []
        for k in range(r.n_frames):
            t = time.perf_counter()
            r.read_frame(k)
            ms.append(1e3 * (time.perf_counter() - t))
    warm = [m for k, m in enumerate(ms) if k % 16]
    print(
        f"\n100k cloth ({frames.shape[1]} vertices, {len(ms)} frames, 12 bits, {os.cpu_count()} cores) "
        f"read through MotionCodec.read_frame: first frame {ms[0]:.0f} ms (with the one-time "
        f"factorizations), keyframe 16 {ms[16]:.0f} ms, other frames median {np.median(warm):.0f} ms, "
        f"max {max(warm):.0f} ms (target 100 ms); encode {1e3 * t_enc / len(ms):.0f} ms a frame, "
        f"{s['bits_per_vertex_frame']:.1f} b/v/f, max error {s['max_error']:.1e} of the diagonal"
    )
    print("  per frame (ms): " + " ".join(f"{m:.0f}" for m in ms))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="16 frames, three levels")
    ap.add_argument("--png", default=str(ROOT / "docs" / "codec-curve.png"))
    args = ap.parse_args()
    angle_bits = [10, 12, 14] if args.quick else [9, 10, 11, 12, 13, 14, 16]
    pos_bits = [8, 11, 14] if args.quick else [7, 8, 9, 10, 11, 12, 13, 14, 16]
    results = {}
    print(f"angle codec vs position coding ({os.cpu_count()} cores)")
    for key in ("flag", "tablecloth"):
        faces, frames = load(key)
        if args.quick:
            frames = frames[:16]
        t, n = frames.shape[:2]
        allp = frames.reshape(-1, 3)
        diag = np.linalg.norm(allp.max(0) - allp.min(0))
        f32 = np.linalg.norm(frames.astype(np.float32) - frames, axis=2) / diag
        rows = [("float32", 96.0, f32.max(), np.sqrt((f32**2).mean()))]
        raw16 = madder.position_baseline_stats(frames, 16, predict=False)
        rows.append(("positions 16-bit raw", raw16["bits_per_vertex_frame"], raw16["max_error"], raw16["rms_error"]))
        pos = []
        for b in pos_bits:
            s = madder.position_baseline_stats(frames, b)
            pos.append((b, s))
            rows.append((f"positions {b}-bit + temporal", s["bits_per_vertex_frame"], s["max_error"], s["rms_error"]))
        ang = []
        for b in angle_bits:
            s = angle_codec(faces, frames, b)
            ang.append((b, s))
            rows.append(
                (
                    f"angles {b}-bit (enc {s['seconds']:.1f} s, dec {s['decode_seconds']:.1f} s)",
                    s["bits_per_vertex_frame"],
                    s["max_error"],
                    s["rms_error"],
                )
            )
        once = angle_codec(faces, frames, 12, corners="once")
        rows.append(
            ("angles 12-bit, corners once", once["bits_per_vertex_frame"], once["max_error"], once["rms_error"])
        )
        print(f"\n{key}: {n} vertices, {t} frames, diagonal {diag:.3f}")
        print(f"{'coder':<48} {'b/v/f':>7} {'max/diag':>10} {'rms/diag':>10}")
        for name, bpvf, mx, rms in rows:
            print(f"{name:<48} {bpvf:7.2f} {mx:10.2e} {rms:10.2e}")
        results[key] = (pos, ang, raw16, once)
    print(
        "\nDynapack (published): "
        + ", ".join(f"{b}-bit {v} b/v/f" + (f" at {e:.1e}" if e else "") for b, v, e in DYNAPACK)
    )
    plot(results, args.png)
    decode_100k()


def plot(results, png):
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib missing: no plot")
        return
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    for ax, (key, (pos, ang, raw16, once)) in zip(axes, results.items(), strict=True):
        ax.plot(
            [s["max_error"] for _, s in ang],
            [s["bits_per_vertex_frame"] for _, s in ang],
            "o-",
            c="C3",
            label="angles, max error",
        )
        ax.plot(
            [s["rms_error"] for _, s in ang],
            [s["bits_per_vertex_frame"] for _, s in ang],
            "o--",
            c="C3",
            alpha=0.5,
            label="angles, RMS error",
        )
        for b, s in ang:
            ax.annotate(
                str(b),
                (s["max_error"], s["bits_per_vertex_frame"]),
                fontsize=7,
                xytext=(3, 3),
                textcoords="offset points",
            )
        ax.plot(
            [s["max_error"] for _, s in pos],
            [s["bits_per_vertex_frame"] for _, s in pos],
            "s-",
            c="C0",
            label="positions + temporal, max",
        )
        for b, s in pos:
            ax.annotate(
                str(b),
                (s["max_error"], s["bits_per_vertex_frame"]),
                fontsize=7,
                xytext=(3, -9),
                textcoords="offset points",
            )
        ax.plot([raw16["max_error"]], [48], "^", c="C2", label="positions 16-bit raw")
        ax.plot([once["max_error"]], [once["bits_per_vertex_frame"]], "x", c="C4", label="angles 12-bit, corners once")
        ax.plot(
            [e for _, _, e in DYNAPACK if e],
            [v for _, v, e in DYNAPACK if e],
            "*",
            ms=11,
            c="k",
            label="Dynapack (published)",
        )
        ax.set_xscale("log")
        ax.set_title(key)
        ax.set_xlabel("error / bounding-box diagonal")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("bits per vertex per frame")
    axes[0].legend(fontsize=7)
    fig.suptitle("Angle codec vs position coding (same range coder)")
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    print(f"wrote {png}")


if __name__ == "__main__":
    main()

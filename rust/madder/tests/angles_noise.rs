//! The noise study of seed §3.4 (Fig. 3.3, Fig. 3.6): uniform noise of ±n % of each angle;
//! closed meshes at 10/20/30 % on the dihedral angles, open meshes at 0.5/1/2 % on every
//! angle. The error is the Procrustes RMS distance (with scale, computed in the test) over
//! the bounding-box diagonal, for the spectral method, the spectral method with 30 steps of
//! descent, the tracked reconstruction started from the spectral one (the codec's keyframe
//! decode), and the sequential baseline; the spectral method must beat the baseline at
//! every level, the tracked fit must settle and beat it too, and the descent must never
//! raise the angle residual.
//!
//! With `MADDER_ANGLES_NOISE_CSV=path` the figures are also written there (what
//! `tests/bench/angles_noise.py` plots into `docs/angles-noise.png`).

mod angles_common;

use angles_common::*;
use madder::angles::{AngleMesh, ReconstructOptions};

const TRIALS: u64 = 3;

struct Row {
    mesh: &'static str,
    level: f64,
    spectral: f64,
    refined: f64,
    tracked: f64,
    sequential: f64,
    residual_voted: f64,
    residual_refined: f64,
}

fn study(name: &'static str, (f, x): Mesh, levels: &[f64], closed: bool, rows: &mut Vec<Row>) {
    let mesh = AngleMesh::new(x.len(), f).unwrap();
    let exact = mesh.encode(&x).unwrap();
    for &level in levels {
        let (mut s, mut r, mut q, mut e0, mut e1) = (0.0, 0.0, 0.0, 0.0, 0.0);
        let mut t = 0.0;
        for trial in 0..TRIALS {
            let corner = if closed { 0.0 } else { level };
            let a = noisy(&exact, corner, level, 1000 * trial + (10.0 * level) as u64);
            let plain = mesh
                .reconstruct(&a, &ReconstructOptions::default())
                .unwrap();
            let opts = ReconstructOptions {
                refine_iterations: 30,
                ..Default::default()
            };
            let refined = mesh.reconstruct(&a, &opts).unwrap();
            for w in refined.residual.windows(2) {
                assert!(
                    w[1] <= w[0],
                    "{name} {level} %: residual rose {:?}",
                    refined.residual
                );
            }
            let seq = mesh.sequential(&a, None).unwrap();
            let tracked = mesh
                .reconstruct_tracked(&a, &plain.positions, &ReconstructOptions::default())
                .unwrap()
                .unwrap_or_else(|| panic!("{name} {level} %: the tracked fit did not settle"));
            t += procrustes_rms(&tracked.positions, &x);
            s += procrustes_rms(&plain.positions, &x);
            r += procrustes_rms(&refined.positions, &x);
            q += procrustes_rms(&seq, &x);
            e0 += refined.residual[0];
            e1 += refined.residual.last().unwrap();
        }
        let n = TRIALS as f64;
        let row = Row {
            mesh: name,
            level,
            spectral: s / n,
            refined: r / n,
            tracked: t / n,
            sequential: q / n,
            residual_voted: e0 / n,
            residual_refined: e1 / n,
        };
        println!(
            "{name:8} {level:5.1} %  spectral {:.3e}  +descent {:.3e}  tracked {:.3e}  sequential {:.3e}  residual {:.3e} -> {:.3e}",
            row.spectral,
            row.refined,
            row.tracked,
            row.sequential,
            row.residual_voted,
            row.residual_refined
        );
        assert!(
            row.tracked < row.sequential,
            "{name} at {level} %: tracked {:e} vs sequential {:e}",
            row.tracked,
            row.sequential
        );
        assert!(
            row.spectral < row.sequential,
            "{name} at {level} %: spectral {:e} vs sequential {:e}",
            row.spectral,
            row.sequential
        );
        rows.push(row);
    }
}

#[test]
fn spectral_beats_sequential_at_every_noise_level() {
    let mut rows = Vec::new();
    let closed = [10.0, 20.0, 30.0];
    let open = [0.5, 1.0, 2.0];
    study("blob", blob(3), &closed, true, &mut rows);
    study("torus", torus(40, 16), &closed, true, &mut rows);
    study("genus2", genus2(3), &closed, true, &mut rows);
    study("sheet", sheet(24), &open, false, &mut rows);
    study("flag", flag(0.4), &open, false, &mut rows);
    if let Ok(path) = std::env::var("MADDER_ANGLES_NOISE_CSV") {
        let mut out = String::from(
            "mesh,level_pct,spectral,spectral_descent,tracked,sequential,residual_voted,residual_descent\n",
        );
        for r in &rows {
            out += &format!(
                "{},{},{:e},{:e},{:e},{:e},{:e},{:e}\n",
                r.mesh,
                r.level,
                r.spectral,
                r.refined,
                r.tracked,
                r.sequential,
                r.residual_voted,
                r.residual_refined
            );
        }
        std::fs::write(path, out).unwrap();
    }
}

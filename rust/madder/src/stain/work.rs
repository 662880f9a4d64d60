//! What a step must move and compute at least (issue 16, target 4): a work model of the
//! simulator's phases, evaluated on the counters of a [`Profile`], so that a benchmark can
//! print, next to each phase's measured time, the bytes it cannot avoid moving, the
//! floating-point operations it cannot avoid doing, and how far it is from the machine's
//! limit for that much work.
//!
//! ## The model
//! Every phase reads its inputs once and writes its outputs once per sweep; a sparse
//! matrix is read once per product or triangular solve (values `f64` and column indices
//! `u32`: 12 bytes an entry), a vector once per use (8 bytes an entry). Nothing is
//! counted twice because an implementation happens to read it twice, and nothing is
//! counted for scratch an implementation could avoid (gathers into window order,
//! interleaving, allocation). So the bytes are a lower bound, as the roofline needs;
//! whether those bytes come from DRAM or from a cache depends on the window's size, and
//! the benchmark picks the bandwidth of the level its per-sub-step working set fits in.
//! The flops count additions and multiplications; a `sqrt`, `exp`, `sin`, `cos` or
//! `atan2` counts [`TRANSCENDENTAL`] (about what a vectorized libm spends).
//!
//! Counts per sub-step, over the window: `n` vertices, `a` active ones, `e` edges, `f`
//! faces; the scalar matrix has `n + 2e` entries and its IC(0) factor `n + e`, the
//! velocity's 2×2-block matrix four times as many. Per phase (B bytes, F flops):
//!
//! | phase | what it must touch | B | F |
//! |---|---|---|---|
//! | geometry | positions, rest positions and frames in; edge lengths, face areas and cotangents, lumped areas, vertex frames, polar angles and `R_ij` out | `216n + 64e + 44f` | `38f + 125e + 650n` (a 3×3 SVD per vertex, a polar angle per spoke, `R_ij` per edge) |
//! | forces | both frames, the acceleration and the velocity in; the kicks, the mean velocity and the extension out | `296n + 32e` | `200n` (two friction exponentials per kick) |
//! | advection | the back-trace (velocities, spoke angles and lengths in, `a` velocities out), the dual fluxes (positions, frames, velocities in, a flux per edge out), the plan (a fraction per edge), and per transport sub-cycle the plan and each carried field | `200n + 65e + 12f + 16a + 17e·C + 16n·P` | `300a + 60f + 24e + 4e·P` |
//! | diffusion | assembly (cotangents, areas, `R_ij` in; the density matrix and the velocity's rotated values out), the densities' IC(0) factor, per solve the right-hand side, warm start and restoration, per CG iteration the matrix, the factor twice (the velocity: its rotated values twice, product and Gauss–Seidel sweeps) and five vectors, per carried field its fluxes | see [`Profile::least_work`] | idem |
//! | interaction | the eleven per-vertex fields in and out, the wetness and the exposure | `208n + 8e` | `80n` |
//! | window | per frame, the search for the liquid (five fields and the area of each window vertex, a mask, the fans of the rings it grows over); per rebuild, the window's faces, edges, fans, both patterns, rest positions and frames written once | `57n + 8e` a frame, `140n + 40e + 12f` a rebuild (window means) | 0 |
//!
//! with `C` the transport sub-cycles and `P` the fields carried times the sub-cycles.

use super::simulate::Profile;

/// Flops counted for one transcendental function (`sqrt`, `exp`, `sin`, `cos`, `atan2`).
pub const TRANSCENDENTAL: f64 = 20.0;

/// The least work of one phase over the steps a [`Profile`] counted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhaseWork {
    /// The phase, as named in [`Profile`].
    pub name: &'static str,
    /// Measured wall-clock seconds.
    pub seconds: f64,
    /// Bytes the phase must move at least.
    pub bytes: f64,
    /// Floating-point operations it must do at least.
    pub flops: f64,
    /// The bytes of one sweep of the phase (per sub-step, or per rebuild for the window):
    /// the working set that decides which memory level serves it.
    pub working_set: f64,
}

impl Profile {
    /// The least bytes and flops of each phase (module doc) over the sub-steps counted,
    /// beside its measured time: window, geometry, forces, advection, diffusion,
    /// interaction.
    pub fn least_work(&self) -> [PhaseWork; 6] {
        let s = self.substeps.max(1) as f64;
        let (n, a) = (self.window_vertices as f64, self.active_vertices as f64);
        let (e, f) = (self.window_edges as f64, self.window_faces as f64);
        // per sub-step means, for the terms counted per cycle, iteration or solve
        let (nm, em) = (n / s, e / s);
        let cycles = self.transport_cycles as f64;
        let passes = self.transport_passes as f64;
        let (nnz_s, fac_s) = (nm + 2.0 * em, nm + em);
        let t = TRANSCENDENTAL;

        let geometry = (
            216.0 * n + 64.0 * e + 44.0 * f,
            (30.0 + t / 2.5) * f + (85.0 + 2.0 * t) * e + (600.0 + 2.5 * t) * n,
        );
        let forces = (296.0 * n + 32.0 * e, (160.0 + 2.0 * t) * n);
        let advection = (
            200.0 * n + 65.0 * e + 12.0 * f + 16.0 * a + 17.0 * em * cycles + 16.0 * nm * passes,
            (260.0 + 2.0 * t) * a + 60.0 * f + 24.0 * e + 4.0 * em * passes,
        );
        // diffusion: assembly and factorizations per sub-step, then per solve and per
        // iteration (module doc)
        // the velocity's values: `(a c, a s)` per scalar entry (`ops/cg/rotated.rs`, "Rotated
        // blocks"), 16 bytes and two products; only the densities' matrix is factored
        let assembly = (
            36.0 * f + 8.0 * n + 16.0 * e + (8.0 + 16.0) * nnz_s * s,
            10.0 * f + 2.0 * nnz_s * s,
        );
        let factor = ((12.0 * nnz_s + 8.0 * fac_s) * s, 6.0 * fac_s * s);
        let solves = self.density_solves as f64 + s; // each density field, and the velocity
        let per_solve = (48.0 * nm + 12.0 * nnz_s, 10.0 * nm + 2.0 * nnz_s);
        let iteration = |nnz: f64, fac: f64, vec: f64| {
            (
                12.0 * nnz + 24.0 * fac + 136.0 * vec,
                2.0 * nnz + 4.0 * fac + 10.0 * vec,
            )
        };
        let dens = iteration(nnz_s, fac_s, nm);
        // the product and the two Gauss–Seidel sweeps each read the rotated values once
        // (20 bytes an entry with its index), 8 flops an entry each
        let vel = (
            40.0 * nnz_s + 136.0 * 2.0 * nm,
            16.0 * nnz_s + 10.0 * 2.0 * nm,
        );
        let (di, vi) = (
            self.density_iterations as f64,
            self.velocity_iterations as f64,
        );
        let carried = self.carried_fields as f64;
        let diffusion = (
            assembly.0
                + factor.0
                + solves * per_solve.0
                + di * dens.0
                + vi * vel.0
                + carried * (24.0 * em + 16.0 * nm),
            assembly.1
                + factor.1
                + solves * per_solve.1
                + di * dens.1
                + vi * vel.1
                + carried * 4.0 * em,
        );
        let interaction = (208.0 * n + 8.0 * e, (40.0 + 2.0 * t) * n);
        let rebuilds = self.window_rebuilds as f64;
        let window_sweep = 140.0 * nm + 40.0 * em + 12.0 * f / s;
        let search = 57.0 * nm + 8.0 * em;
        let window = (rebuilds * window_sweep + self.frames as f64 * search, 0.0);

        let phase = |name, seconds, (bytes, flops): (f64, f64), working_set| PhaseWork {
            name,
            seconds,
            bytes,
            flops,
            working_set,
        };
        [
            phase("window", self.window, window, window_sweep),
            phase("geometry", self.geometry, geometry, geometry.0 / s),
            phase("forces", self.forces, forces, forces.0 / s),
            phase("advection", self.advection, advection, advection.0 / s),
            phase(
                "diffusion",
                self.diffusion,
                diffusion,
                12.0 * nnz_s + 8.0 * fac_s + 20.0 * nnz_s + 136.0 * 3.0 * nm,
            ),
            phase(
                "interaction",
                self.interaction,
                interaction,
                interaction.0 / s,
            ),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The model is linear in the counters: doubling every counter (twice the sub-steps
    /// of the same size) doubles every phase's bytes and flops and keeps the working set.
    #[test]
    fn least_work_scales_with_the_counters() {
        let one = Profile {
            frames: 2,
            substeps: 3,
            window_vertices: 3 * 1000,
            active_vertices: 3 * 800,
            window_edges: 3 * 2900,
            window_faces: 3 * 1900,
            transport_cycles: 7,
            transport_passes: 14,
            density_iterations: 20,
            velocity_iterations: 9,
            density_solves: 6,
            carried_fields: 24,
            window_rebuilds: 1,
            ..Default::default()
        };
        let two = Profile {
            frames: 4,
            substeps: 6,
            window_vertices: 6 * 1000,
            active_vertices: 6 * 800,
            window_edges: 6 * 2900,
            window_faces: 6 * 1900,
            transport_cycles: 14,
            transport_passes: 28,
            density_iterations: 40,
            velocity_iterations: 18,
            density_solves: 12,
            carried_fields: 48,
            window_rebuilds: 2,
            ..Default::default()
        };
        for (p, q) in one.least_work().iter().zip(&two.least_work()) {
            assert!(
                (q.bytes - 2.0 * p.bytes).abs() <= 1e-9 * q.bytes,
                "{}",
                p.name
            );
            assert!((q.flops - 2.0 * p.flops).abs() <= 1e-9 * q.flops.max(1.0));
            assert!((q.working_set - p.working_set).abs() <= 1e-9 * p.working_set);
        }
        // one more CG iteration of the densities costs one sweep of the scalar matrix
        // (12 bytes an entry), its factor twice and five vectors' worth of traffic
        let more = Profile {
            density_iterations: 21,
            ..one
        };
        let extra = more.least_work()[4].bytes - one.least_work()[4].bytes;
        let (n, e) = (1000.0, 2900.0);
        let expected = 12.0 * (n + 2.0 * e) + 24.0 * (n + e) + 136.0 * n;
        assert!((extra - expected).abs() < 1e-6, "{extra} vs {expected}");
    }
}

//! `make bench`: time per frame of implicit diffusion on a deforming cloth-like grid, split
//! into its parts (geometry, assembly, numeric factorization, solve), and what reusing the
//! symbolic analysis saves. Prints figures; asserts nothing about time.

mod common;

use std::time::Instant;

use common::{grid, wave};
use faer::Par;
use glam::DVec3;
use madder::mesh::Geometry;
use madder::ops::{PrefactoredSpd, VertexPattern, WarmCg, add_lumped_mass, cotan_stiffness};
use madder::stain::{Conductivity, DiffusionStepper};

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

fn bench(nx: usize, ny: usize, frames: usize) {
    let (topo, rest) = grid(nx, ny);
    let n = topo.n_vertices();
    let t = Instant::now();
    let pattern = VertexPattern::new(&topo);
    let mut solver = PrefactoredSpd::new(pattern.clone(), Par::Seq).unwrap();
    let symbolic = ms(t);

    let (mut geo, mut asm, mut fact, mut solve) = (0.0, 0.0, 0.0, 0.0);
    for f in 0..frames {
        let p = wave(&rest, f as f64 / 24.0);
        let t = Instant::now();
        let g = Geometry::new(&topo, &p).unwrap();
        geo += ms(t);
        let t = Instant::now();
        let mut v = cotan_stiffness(&topo, &g, &pattern, 0.002 / 24.0);
        add_lumped_mass(&g, &pattern, 1.0, &mut v);
        asm += ms(t);
        let t = Instant::now();
        solver.factorize(&v).unwrap();
        fact += ms(t);
        let mut rhs = g.vertex_area.clone();
        let t = Instant::now();
        solver.solve_in_place(&mut rhs);
        solve += ms(t);
    }
    let k = frames as f64;
    let d0: Vec<f64> = rest
        .iter()
        .map(|p| (-(p.distance_squared(DVec3::new(1.0, 0.0, 0.6))) / 0.02).exp())
        .collect();
    let mut s =
        DiffusionStepper::new(topo, &rest, d0, Conductivity::Isotropic(0.002), Par::Seq).unwrap();
    let t = Instant::now();
    for f in 1..=frames {
        s.step(&wave(&rest, f as f64 / 24.0), 1.0 / 24.0, 1)
            .unwrap();
    }
    let step = ms(t) / k;
    println!(
        "{n:>7} vertices: step {step:7.2} ms/frame  [geometry {:.2}, assembly {:.2}, numeric factorization {:.2}, solve {:.2}]  symbolic analysis (once per bake) {symbolic:.1} ms",
        geo / k,
        asm / k,
        fact / k,
        solve / k
    );
}

/// The same steps with faer's conjugate gradient (Jacobi preconditioner), warm-started
/// from the previous frame's solution, instead of refactorizing: the comparison issue 3
/// asks for. Also reports CG's mass defect, since CG conserves mass only to its tolerance.
fn bench_cg(nx: usize, ny: usize, frames: usize, rel_tol: f64) {
    let (topo, rest) = grid(nx, ny);
    let n = topo.n_vertices();
    let pattern = VertexPattern::new(&topo);
    let mut cg = WarmCg::new(&pattern).with_tolerance(rel_tol);
    let mut density: Vec<f64> = rest
        .iter()
        .map(|p| (-(p.distance_squared(DVec3::new(1.0, 0.0, 0.6))) / 0.02).exp())
        .collect();
    let mut g = Geometry::new(&topo, &rest).unwrap();
    let (mut t_total, mut iters, mut worst_mass) = (0.0, 0usize, 0.0f64);
    for f in 1..=frames {
        let t = Instant::now();
        let p = wave(&rest, f as f64 / 24.0);
        let g_new = Geometry::new(&topo, &p).unwrap();
        let mut v = cotan_stiffness(&topo, &g_new, &pattern, 0.002 / 24.0);
        add_lumped_mass(&g_new, &pattern, 1.0, &mut v);
        let rhs: Vec<f64> = (0..n).map(|i| g.vertex_area[i] * density[i]).collect();
        // warm start: the previous frame's density
        let mut x = density.clone();
        cg.solve(&v, &rhs, &mut x).unwrap();
        t_total += ms(t);
        iters += cg.last_iterations;
        let m_before: f64 = rhs.iter().sum();
        let m_after: f64 = (0..n).map(|i| g_new.vertex_area[i] * x[i]).sum();
        worst_mass = worst_mass.max(((m_after - m_before) / m_before).abs());
        density = x;
        g = g_new;
    }
    println!(
        "{n:>7} vertices: warm-started Jacobi-PCG (rel. tol {rel_tol:.0e}) {:7.2} ms/frame, {:.1} iterations/frame, worst relative mass change per step {worst_mass:.1e}",
        t_total / frames as f64,
        iters as f64 / frames as f64
    );
}

fn main() {
    println!(
        "implicit diffusion (M + hDK)σ' = m on a waving flag grid, {} rayon threads, faer Par::Seq",
        rayon::current_num_threads()
    );
    bench(127, 77, 48); // ≈ 10k vertices
    bench(407, 245, 12); // ≈ 100k vertices
    println!(
        "the same frames with an iterative solver (geometry, assembly and the solve included):"
    );
    for tol in [1e-8, 1e-12] {
        bench_cg(127, 77, 48, tol);
        bench_cg(407, 245, 12, tol);
    }
}

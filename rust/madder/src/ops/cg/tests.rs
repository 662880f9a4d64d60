use super::*;
use crate::error::SolveError;
use crate::mesh::{Geometry, OneRings, Topology, Transport, VertexFrames};
use crate::ops::solve::LowerCsc;
use crate::ops::{
    BochnerPattern, PrefactoredSpd, Restriction, VertexPattern, add_lumped_mass,
    add_lumped_mass_blocks, anisotropic_stiffness, bochner_stiffness, cotan_stiffness,
};
use faer::Par;
use glam::DVec3;

#[test]
fn matches_cholesky_on_a_mass_plus_stiffness_system() {
    // a 12×12 jittered grid, h D large enough that K matters
    let n = 12;
    let mut pos = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let jit = ((i * 7 + j * 13) % 5) as f64 * 0.01;
            pos.push(DVec3::new(i as f64 * 0.1 + jit, j as f64 * 0.1 - jit, 0.0));
        }
    }
    let topo = crate::mesh::topology::grid_topology(n, n);
    let geom = Geometry::new(&topo, &pos).unwrap();
    let pattern = VertexPattern::new(&topo);
    let mut values = cotan_stiffness(&topo, &geom, &pattern, 0.05);
    add_lumped_mass(&geom, &pattern, 1.0, &mut values);
    let b: Vec<f64> = (0..2 * n * n)
        .map(|i| ((i * 31 % 17) as f64).sin())
        .collect();
    let mut direct = b.clone();
    let mut chol = PrefactoredSpd::new(pattern.clone(), Par::Seq).unwrap();
    chol.factorize(&values).unwrap();
    chol.solve_in_place(&mut direct);
    let mut cg = WarmCg::new(&pattern);
    let mut x = vec![0.0; b.len()];
    cg.solve(&values, &b, &mut x).unwrap();
    let err = x
        .iter()
        .zip(&direct)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    let scale = direct.iter().map(|v| v.abs()).fold(0.0, f64::max);
    assert!(err < 1e-10 * scale, "CG vs Cholesky: {err:e}");
    // warm-started from the solution, it converges at once
    cg.solve(&values, &b, &mut x).unwrap();
    assert!(cg.last_iterations <= 2, "{}", cg.last_iterations);
}

/// A grid sheared by `shear` (obtuse triangles for `shear` ≳ 0.5) with a little
/// jitter, optionally bent around a cylinder (a curved surface: non-trivial
/// connection).
fn sheared_mesh(n: usize, shear: f64, bend: bool) -> (Topology, Vec<DVec3>) {
    let mut pos = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let jit = ((i * 7 + j * 13) % 5) as f64 * 0.01;
            let (u, v) = (
                i as f64 * 0.1 + shear * j as f64 * 0.1 + jit,
                j as f64 * 0.1,
            );
            pos.push(if bend {
                DVec3::new(u.sin(), v - jit, u.cos())
            } else {
                DVec3::new(u, v - jit, 0.0)
            });
        }
    }
    (crate::mesh::topology::grid_topology(n, n), pos)
}

/// `M + K_S` on the sheared mesh, `S` anisotropic (4:1, off the grid axes), scaled so
/// that `K` dominates: not an M-matrix (positive off-diagonal entries).
fn obtuse_anisotropic_system(n: usize) -> (VertexPattern, Vec<f64>) {
    let (topo, pos) = sheared_mesh(n, 0.8, false);
    let geom = Geometry::new(&topo, &pos).unwrap();
    let pattern = VertexPattern::new(&topo);
    let nf = topo.n_faces();
    let mut values = anisotropic_stiffness(
        &topo,
        &geom,
        &pattern,
        &vec![0.4; nf],
        &vec![[1.0, 0.2, 0.25]; nf],
        0.1,
    );
    add_lumped_mass(&geom, &pattern, 1.0, &mut values);
    (pattern, values)
}

fn max_error(x: &[f64], reference: &[f64]) -> f64 {
    let err = x
        .iter()
        .zip(reference)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    err / reference.iter().map(|v| v.abs()).fold(0.0, f64::max)
}

#[test]
fn preconditioners_match_cholesky_on_an_obtuse_anisotropic_mesh() {
    let n = 16;
    let (pattern, values) = obtuse_anisotropic_system(n);
    // not an M-matrix: some off-diagonal entries are positive
    let positive = (0..n * n)
        .flat_map(|j| pattern.col_ptr()[j] + 1..pattern.col_ptr()[j + 1])
        .filter(|&s| values[s as usize] > 0.0)
        .count();
    assert!(positive > 0, "the test system is an M-matrix");
    let b: Vec<f64> = (0..2 * n * n)
        .map(|i| ((i * 31 % 17) as f64).sin())
        .collect();
    let mut direct = b.clone();
    let mut chol = PrefactoredSpd::new(pattern.clone(), Par::Seq).unwrap();
    chol.factorize(&values).unwrap();
    chol.solve_in_place(&mut direct);
    let mut iterations = Vec::new();
    for p in [
        Preconditioner::Jacobi,
        Preconditioner::SymmetricGaussSeidel,
        Preconditioner::IncompleteCholesky,
    ] {
        let mut cg = WarmCg::new(&pattern).with_preconditioner(p);
        let mut x = vec![0.0; b.len()];
        cg.solve(&values, &b, &mut x).unwrap();
        let err = max_error(&x, &direct);
        assert!(err < 1e-9, "{p:?} vs Cholesky: {err:e}");
        iterations.push(cg.last_iterations);
        if p == Preconditioner::IncompleteCholesky {
            assert_eq!(cg.last_shift, 0.0, "IC(0) needed a shift");
        }
    }
    // the default is IC(0), and it pays: fewer iterations than Jacobi
    assert_eq!(
        WarmCg::new(&pattern).precond,
        Preconditioner::IncompleteCholesky
    );
    assert!(iterations[2] < iterations[0], "{iterations:?}");
}

/// The Bochner system (stiffness plus lumped mass) of a sheared `n × n` grid.
fn bochner_system(n: usize) -> (BochnerPattern, Vec<f64>) {
    let (topo, pos) = sheared_mesh(n, 0.3, true);
    let geom = Geometry::new(&topo, &pos).unwrap();
    let rings = OneRings::new(&topo);
    let frames = VertexFrames::new(&rings, &pos).unwrap();
    let transport = Transport::new(&topo, &rings, &geom, &frames, &pos);
    let scalar = VertexPattern::new(&topo);
    let pattern = BochnerPattern::new(&scalar);
    let stiffness = cotan_stiffness(&topo, &geom, &scalar, 0.05);
    let mut values = bochner_stiffness(&scalar, &pattern, &stiffness, &transport);
    add_lumped_mass_blocks(&geom, &pattern, 1.0, &mut values);
    (pattern, values)
}

#[test]
fn bochner_block_system_still_solves() {
    let n = 12;
    let (pattern, values) = bochner_system(n);
    let b: Vec<f64> = (0..2 * n * n)
        .map(|i| ((i * 7 % 11) as f64).cos())
        .collect();
    let mut direct = b.clone();
    let mut chol = PrefactoredSpd::new(pattern.clone(), Par::Seq).unwrap();
    chol.factorize(&values).unwrap();
    chol.solve_in_place(&mut direct);
    for p in [Preconditioner::Jacobi, Preconditioner::IncompleteCholesky] {
        let mut cg = WarmCg::new(&pattern)
            .with_tolerance(1e-12)
            .with_preconditioner(p);
        let mut x = vec![0.0; b.len()];
        cg.solve(&values, &b, &mut x).unwrap();
        let err = max_error(&x, &direct);
        assert!(err < 1e-9, "{p:?} vs Cholesky: {err:e}");
        // warm-started from the solution, it converges at once
        cg.solve(&values, &b, &mut x).unwrap();
        assert!(cg.last_iterations <= 2, "{p:?}: {}", cg.last_iterations);
    }
}

/// The velocity's solve without the block expansion is the expanded system's Jacobi
/// solve to the last bit, on a restriction (a partial mask, so the edges' rotations
/// are looked up through the restricted entries), and it solves the system.
#[test]
fn rotated_blocks_solve_as_the_expanded_system_bit_for_bit() {
    let n = 14;
    let (topo, pos) = sheared_mesh(n, 0.3, true);
    let geom = Geometry::new(&topo, &pos).unwrap();
    let rings = OneRings::new(&topo);
    let frames = VertexFrames::new(&rings, &pos).unwrap();
    let transport = Transport::new(&topo, &rings, &geom, &frames, &pos);
    let scalar = VertexPattern::new(&topo);
    let mask: Vec<bool> = (0..n * n).map(|v| (v % n) + v / n > 4).collect();
    let region = Restriction::new(&scalar, mask);
    let stiffness = cotan_stiffness(&topo, &geom, &scalar, 0.05);
    let values = region.scalar_values(&scalar, &stiffness, &geom.vertex_area, true);
    let blocks = region.bochner_values(&values, &transport);
    let m = region.vertices.len();
    let b: Vec<f64> = (0..2 * m).map(|i| ((i * 7 % 11) as f64).cos()).collect();
    let start: Vec<f64> = b.iter().map(|v| 0.8 * v).collect();
    let mut expanded = WarmCg::new(region.bochner())
        .with_tolerance(1e-10)
        .with_preconditioner(Preconditioner::Jacobi);
    let mut x = start.clone();
    expanded.solve(&blocks, &b, &mut x).unwrap();
    let mut rotated = WarmCg::new(region.scalar())
        .with_tolerance(1e-10)
        .with_preconditioner(Preconditioner::Jacobi);
    let mut y = start.clone();
    rotated
        .solve_rotated(
            &values,
            region.entry_edges(),
            transport.edge_cos_sin(),
            &b,
            &mut y,
        )
        .unwrap();
    assert!(expanded.last_iterations > 2);
    assert_eq!(rotated.last_iterations, expanded.last_iterations);
    assert!(x.iter().zip(&y).all(|(a, b)| a.to_bits() == b.to_bits()));
    // and it is the solution: against the Cholesky factorization of the blocks
    let mut direct = b.clone();
    let mut chol = PrefactoredSpd::new(region.bochner().clone(), Par::Seq).unwrap();
    chol.factorize(&blocks).unwrap();
    chol.solve_in_place(&mut direct);
    assert!(
        max_error(&y, &direct) < 1e-8,
        "{:e}",
        max_error(&y, &direct)
    );
    // with symmetric Gauss–Seidel on the blocks (the simulator's): the same solution
    // in fewer iterations, deterministic
    let sgs = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                let mut cg = WarmCg::new(region.scalar())
                    .with_tolerance(1e-10)
                    .with_preconditioner(Preconditioner::SymmetricGaussSeidel);
                let mut y = start.clone();
                let (edges, cos_sin) = (region.entry_edges(), transport.edge_cos_sin());
                cg.solve_rotated(&values, edges, cos_sin, &b, &mut y)
                    .unwrap();
                (y, cg.last_iterations)
            })
    };
    let ((s1, it1), (s2, it2)) = (sgs(1), sgs(2));
    assert!(
        max_error(&s1, &direct) < 1e-8,
        "{:e}",
        max_error(&s1, &direct)
    );
    assert!(
        it1 < rotated.last_iterations,
        "{it1} vs {}",
        rotated.last_iterations
    );
    assert_eq!(it1, it2);
    assert!(s1.iter().zip(&s2).all(|(a, b)| a.to_bits() == b.to_bits()));
    // a zero right-hand side gives zero at once; a non-positive diagonal is an error
    let mut z = start.clone();
    rotated
        .solve_rotated(
            &values,
            region.entry_edges(),
            transport.edge_cos_sin(),
            &vec![0.0; 2 * m],
            &mut z,
        )
        .unwrap();
    assert!(z.iter().all(|&v| v == 0.0) && rotated.last_iterations == 0);
    let mut bad = values.clone();
    bad[region.scalar().col_ptr()[3] as usize] = -1.0;
    let err = rotated.solve_rotated(
        &bad,
        region.entry_edges(),
        transport.edge_cos_sin(),
        &b,
        &mut z,
    );
    assert!(matches!(
        err,
        Err(SolveError::NotPositiveDefinite { pivot: 6, .. })
    ));
}

/// A solve of a fixed right-hand side for an `m`-vertex block system: the solution
/// and the iterations.
fn solve(cg: &mut WarmCg, values: &[f64], m: usize) -> (Vec<f64>, usize) {
    let b: Vec<f64> = (0..2 * m).map(|i| ((i * 7 % 11) as f64).cos()).collect();
    let mut x = vec![0.0; b.len()];
    cg.solve(values, &b, &mut x).unwrap();
    (x, cg.last_iterations)
}

#[test]
fn rebuilt_in_old_memory_is_new_and_its_updates_are_ic0s() {
    let (block, values) = bochner_system(12);
    let (small, small_values) = obtuse_anisotropic_system(7);
    let m = block.n();
    // large → small → large, against fresh solvers: the same iterations, the same bits
    let mut cg = WarmCg::new(&block).with_tolerance(1e-10);
    solve(&mut cg, &values, m);
    for (pattern, vals) in [(&small as &dyn LowerCsc, &small_values), (&block, &values)] {
        cg.rebuild(pattern);
        let mut fresh = WarmCg::new(pattern).with_tolerance(1e-10);
        let (x, it) = solve(&mut cg, vals, pattern.n());
        let (y, jt) = solve(&mut fresh, vals, pattern.n());
        assert_eq!(it, jt);
        assert!(x.iter().zip(&y).all(|(a, b)| a.to_bits() == b.to_bits()));
        // the updates are every (i, j) in the pattern below two entries of a column k,
        // found here by brute force
        let lower: std::collections::HashSet<(u32, u32)> = (0..cg.n)
            .flat_map(|j| {
                let r = cg.l_ptr[j] as usize..cg.l_ptr[j + 1] as usize;
                cg.l_row[r].iter().map(move |&i| (i, j as u32))
            })
            .collect();
        let mut expected = Vec::new();
        for k in 0..cg.n {
            let (lo, hi) = (cg.l_ptr[k] as usize, cg.l_ptr[k + 1] as usize);
            for q in lo..hi {
                for p in q + 1..hi {
                    let (i, j) = (cg.l_row[p], cg.l_row[q]);
                    if lower.contains(&(i, j)) {
                        let c = cg.l_ptr[j as usize] as usize;
                        let t = c + cg.l_row[c..].iter().position(|&r| r == i).unwrap();
                        expected.push([t as u32, p as u32, q as u32]);
                    }
                }
            }
        }
        assert!(!expected.is_empty());
        assert_eq!(cg.upd, expected);
    }
}

#[test]
fn analysis_left_for_later_is_the_same() {
    // a solver rebuilt with another preconditioner than IC(0) analyses at its first
    // scalar solve (or never, if it only solves rotated): the same bits as a fresh one
    let (block, values) = bochner_system(9);
    let (small, small_values) = obtuse_anisotropic_system(7);
    for (first, then) in [
        (Preconditioner::SymmetricGaussSeidel, None),
        (
            Preconditioner::SymmetricGaussSeidel,
            Some(Preconditioner::IncompleteCholesky),
        ),
        (
            Preconditioner::Jacobi,
            Some(Preconditioner::SymmetricGaussSeidel),
        ),
    ] {
        let mut cg = WarmCg::new(&block)
            .with_tolerance(1e-10)
            .with_preconditioner(first);
        assert!(
            !cg.analyzed,
            "a new solver analyses at its first scalar solve"
        );
        solve(&mut cg, &values, block.n());
        for (pattern, vals) in [(&small as &dyn LowerCsc, &small_values), (&block, &values)] {
            cg.precond = first;
            cg.rebuild(pattern);
            assert!(!cg.analyzed, "{first:?}: analysed before a scalar solve");
            if let Some(p) = then {
                cg.precond = p;
            }
            let mut fresh = WarmCg::new(pattern)
                .with_tolerance(1e-10)
                .with_preconditioner(then.unwrap_or(first));
            let (x, it) = solve(&mut cg, vals, pattern.n());
            let (y, jt) = solve(&mut fresh, vals, pattern.n());
            assert!(cg.analyzed);
            assert_eq!(it, jt);
            assert!(x.iter().zip(&y).all(|(a, b)| a.to_bits() == b.to_bits()));
            assert_eq!(cg.upd, fresh.upd);
            assert_eq!(cg.u_pos, fresh.u_pos);
        }
    }
}

#[test]
fn bit_identical_with_one_or_two_threads() {
    let n = 24;
    let (pattern, values) = obtuse_anisotropic_system(n);
    // three columns, the second a thousand times smaller, solved side by side
    let b: Vec<f64> = (0..3 * n * n)
        .map(|i| ((i * 31 % 17) as f64).sin() * if i / (n * n) == 1 { 1e-3 } else { 1.0 })
        .collect();
    for p in [
        Preconditioner::Jacobi,
        Preconditioner::SymmetricGaussSeidel,
        Preconditioner::IncompleteCholesky,
    ] {
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    let mut cg = WarmCg::new(&pattern)
                        .with_tolerance(1e-9)
                        .with_preconditioner(p);
                    let mut x: Vec<f64> = b.iter().map(|v| 0.9 * v).collect();
                    cg.solve(&values, &b, &mut x).unwrap();
                    let mut y: Vec<f64> = b.iter().map(|v| 0.9 * v).collect();
                    cg.solve_chained(&values, &b, &mut y).unwrap();
                    x.extend(y);
                    (x, cg.last_iterations)
                })
        };
        let ((x1, it1), (x2, it2)) = (run(1), run(2));
        assert_eq!(it1, it2, "{p:?}");
        assert!(
            x1.iter().zip(&x2).all(|(a, b)| a.to_bits() == b.to_bits()),
            "{p:?}: results differ between 1 and 2 threads"
        );
    }
}

#[test]
fn chained_columns_match_cholesky_and_proportional_ones_are_free() {
    let n = 16;
    let (pattern, values) = obtuse_anisotropic_system(n);
    let nn = n * n;
    let b0: Vec<f64> = (0..nn)
        .map(|i| 1.0 + ((i * 31 % 17) as f64).sin())
        .collect();
    // a second, unrelated column, and multiples of the first (colour masses): the
    // warm starts are `b / 2` throughout, as the stepper's `m / A`
    let b1: Vec<f64> = (0..nn).map(|i| ((i * 7 % 11) as f64).cos()).collect();
    let columns = [b0.clone(), b0.iter().map(|v| 0.05 * v).collect(), b1];
    let b: Vec<f64> = columns.iter().flatten().copied().collect();
    let mut direct = b.clone();
    let mut chol = PrefactoredSpd::new(pattern.clone(), Par::Seq).unwrap();
    chol.factorize(&values).unwrap();
    chol.solve_in_place(&mut direct);
    let solve = |chained: bool, b: &[f64]| {
        let mut cg = WarmCg::new(&pattern).with_tolerance(1e-10);
        let mut x: Vec<f64> = b.iter().map(|v| 0.5 * v).collect();
        if chained {
            cg.solve_chained(&values, b, &mut x).unwrap();
        } else {
            cg.solve(&values, b, &mut x).unwrap();
        }
        (x, cg.last_iterations)
    };
    let (x, chained) = solve(true, &b);
    for c in 0..3 {
        let err = max_error(&x[c * nn..(c + 1) * nn], &direct[c * nn..(c + 1) * nn]);
        assert!(err < 1e-8, "column {c} vs Cholesky: {err:e}");
    }
    // the multiple stays a multiple, to rounding (a colour read as mass / solute is
    // the poured colour), as independent solves keep it (CG is scale-invariant)
    let ratio = max_error(
        &x[nn..2 * nn],
        &x[..nn].iter().map(|v| 0.05 * v).collect::<Vec<_>>(),
    );
    assert!(ratio < 1e-14, "proportional column off by {ratio:e}");
    let (_, independent) = solve(false, &b);
    let (_, first) = solve(false, &b0);
    let (_, last) = solve(false, &columns[2]);
    assert_eq!(independent, 2 * first + last);
    // the multiple of the first column starts from its solution: at most one
    // iteration (its residual is the first one's, scaled, plus rounding); the
    // unrelated column, recycled along a direction that does not help, costs at most
    // what it costs alone (the Galerkin step never makes the start worse)
    assert!(chained <= first + 1 + last, "{chained} vs {first} + {last}");
    assert!(chained < independent, "{chained} vs {independent}");
}

/// SPD matrices on a 4-cycle (no chords) whose IC(0) breaks down: the solve shifts
/// the diagonal, or falls back to Jacobi, and still converges.
#[test]
fn incomplete_cholesky_breakdown_falls_back() {
    struct Cycle;
    impl LowerCsc for Cycle {
        fn n(&self) -> usize {
            4
        }
        fn col_ptr(&self) -> &[u32] {
            &[0, 3, 5, 7, 8]
        }
        fn row_idx(&self) -> &[u32] {
            &[0, 1, 3, 1, 2, 2, 3, 3]
        }
    }
    // off-diagonal (1,0), (3,0), (2,1), (3,2); eigenvalues ≥ 0.047 and 0.056
    for (off, shift) in [
        ([-0.27, -0.91, -0.88, 0.28], 0.1),
        ([-0.64, 0.61, -0.67, -0.66], f64::NAN),
    ] {
        let values = [1.0, off[0], off[1], 1.0, off[2], 1.0, off[3], 1.0];
        let x_true = [1.0, -2.0, 0.5, 3.0];
        let mut b = vec![0.0; 4];
        for j in 0..4 {
            for s in Cycle.col_ptr()[j]..Cycle.col_ptr()[j + 1] {
                let (i, v) = (Cycle.row_idx()[s as usize] as usize, values[s as usize]);
                b[i] += v * x_true[j];
                if i != j {
                    b[j] += v * x_true[i];
                }
            }
        }
        let mut cg = WarmCg::new(&Cycle);
        let mut x = vec![0.0; 4];
        cg.solve(&values, &b, &mut x).unwrap();
        assert!(
            cg.last_shift.to_bits() == shift.to_bits(),
            "shift {} instead of {shift}",
            cg.last_shift
        );
        assert!(max_error(&x, &x_true) < 1e-10, "{x:?}");
    }
}

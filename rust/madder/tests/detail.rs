//! Validation of stain Detail (issue 12): the regular refinement of a cloth and the
//! simulator run on it, against exact results:
//!
//! 1. the refined mesh: counts, orientation, no new boundary or non-manifold edges, the
//!    same surface (area) and a linear field reproduced exactly;
//! 2. the transfers: the fine lumped areas restrict to the coarse ones (the identity
//!    `Σ_j A_j φ_i(x_j) = A_i` the mass-exact pour rests on), totals preserved;
//! 3. level 0 is the cloth simulator bit for bit;
//! 4. totals are the same read at the fine and at the cloth level (1e-12), and a pour of
//!    `σ_i` puts exactly `Σ A_i σ_i` on the refined cloth;
//! 5. a stain on a waving cloth converges as the level grows (the L2 difference between
//!    successive levels shrinks);
//! 6. bad input names the cloth's elements; too fine a mesh is refused with the figure.

use faer::Par;
use glam::DVec3;
use madder::mesh::geometry::vertex_areas;
use madder::mesh::{EdgeKind, Refinement, Topology};
use madder::stain::{Conductivity, Detailed, Forces, Simulator, StainParams, WovenFaces};
use madder::{Error, MeshError, ParamError};

mod common;
use common::{Grid, gaussian};

fn kinds(t: &Topology) -> [usize; 3] {
    let mut k = [0; 3];
    for e in 0..t.n_edges() {
        k[match t.edge_kind(e) {
            EdgeKind::Boundary => 0,
            EdgeKind::Interior => 1,
            EdgeKind::NonManifold => 2,
        }] += 1;
    }
    k
}

fn normal(p: &[DVec3], f: [u32; 3]) -> DVec3 {
    let [a, b, c] = f.map(|v| p[v as usize]);
    (b - a).cross(c - a)
}

/// A jittered grid bent into a cylinder-like sheet, so faces are of every shape and not
/// coplanar.
fn bent(n: usize) -> (Topology, Vec<DVec3>) {
    Grid::new(n, 0.5)
        .jitter(0.3)
        .build_with(|x, y| DVec3::new(x, 0.3 * (2.0 * x).sin() + 0.1 * y * y, y))
}

#[test]
fn refined_mesh_is_the_same_surface_split_regularly() {
    let (coarse, pos) = bent(6);
    let [cb, _, cn] = kinds(&coarse);
    for level in 0..=3u32 {
        let r = Refinement::new(&coarse, level).unwrap();
        let fine = r.fine();
        let n = 1usize << level;
        assert_eq!(fine.n_faces(), coarse.n_faces() * n * n);
        let expect_v = coarse.n_vertices()
            + coarse.n_edges() * (n - 1)
            + coarse.n_faces() * (n - 1) * n.saturating_sub(2) / 2;
        assert_eq!(fine.n_vertices(), expect_v, "level {level}");
        // Euler characteristic and the border: refinement changes neither
        let chi = |t: &Topology| t.n_vertices() as i64 - t.n_edges() as i64 + t.n_faces() as i64;
        assert_eq!(chi(fine), chi(&coarse));
        let [fb, _, fnm] = kinds(fine);
        assert_eq!((fb, fnm), (cb * n, cn * n));
        // no loose vertex, every fine vertex on some face
        assert!(fine.loose_vertices().iter().all(|&l| !l));

        let fp = r.prolong(&pos);
        // the fine vertices of level 0 are the cloth's, and cloth vertices keep their index
        assert_eq!(&fp[..coarse.n_vertices()], &pos[..]);
        // same area, same orientation face by face
        let area = |t: &Topology, p: &[DVec3]| -> f64 {
            t.faces().iter().map(|&f| 0.5 * normal(p, f).length()).sum()
        };
        let (a0, a1) = (area(&coarse, &pos), area(fine, &fp));
        assert!((a1 - a0).abs() <= 1e-13 * a0, "area {a0} vs {a1}");
        for (t, &f) in fine.faces().iter().enumerate() {
            let parent = coarse.faces()[r.parent(t)];
            let (nf, nc) = (normal(&fp, f), normal(&pos, parent));
            assert!(nf.dot(nc) > 0.0, "fine face {t} flipped");
            assert!(nf.normalize().dot(nc.normalize()) > 1.0 - 1e-12);
        }
        // a linear field is reproduced exactly at every fine vertex
        let lin = |p: DVec3| 0.3 + 1.7 * p.x - 0.4 * p.y + 2.2 * p.z;
        let fine_lin = r.prolong(&pos.iter().map(|&p| lin(p)).collect::<Vec<_>>());
        for (j, (&v, &p)) in fine_lin.iter().zip(&fp).enumerate() {
            assert!(
                (v - lin(p)).abs() < 1e-13,
                "fine vertex {j}: {v} vs {}",
                lin(p)
            );
        }
        // UVs: the fine faces' UVs are the positions' barycentric combination too
        let uv: Vec<[[f64; 2]; 3]> = coarse
            .faces()
            .iter()
            .map(|f| f.map(|v| [pos[v as usize].x, pos[v as usize].z]))
            .collect();
        for (t, (fuv, f)) in r.face_uv(&uv).iter().zip(fine.faces()).enumerate() {
            for k in 0..3 {
                let p = fp[f[k] as usize];
                assert!(
                    (fuv[k][0] - p.x).abs() < 1e-14 && (fuv[k][1] - p.z).abs() < 1e-14,
                    "face {t}"
                );
            }
        }
    }
}

#[test]
fn fine_areas_restrict_to_the_cloths_and_totals_are_kept() {
    let (coarse, pos) = bent(7);
    let a0 = vertex_areas(&coarse, &pos);
    for level in 1..=3 {
        let r = Refinement::new(&coarse, level).unwrap();
        let fp = r.prolong(&pos);
        let fine_area = vertex_areas(r.fine(), &fp);
        let back = r.restrict(&fine_area);
        for i in 0..a0.len() {
            assert!(
                (back[i] - a0[i]).abs() <= 1e-14 * a0[i].max(1e-3),
                "vertex {i}"
            );
        }
        let m: Vec<f64> = (0..fp.len()).map(|j| ((j * 7919) % 101) as f64).collect();
        let (s0, s1): (f64, f64) = (m.iter().sum(), r.restrict(&m).iter().sum());
        assert!((s0 - s1).abs() <= 1e-13 * s0);
    }
}

fn params() -> StainParams {
    StainParams {
        forces: Forces::default(),
        ..Default::default()
    }
}

/// A hanging, waving sheet over [−0.5, 0.5]² (vertical, so the liquid runs down).
fn hanging(n: usize) -> (Topology, Vec<DVec3>, impl Fn(f64) -> Vec<DVec3>) {
    let grid = Grid::new(n, 0.5).jitter(0.2);
    let (topo, rest) = grid.build_with(|x, y| DVec3::new(x, 0.0, y));
    let at = move |t: f64| {
        grid.positions(|x, y| DVec3::new(x, 0.05 * (3.0 * x - 4.0 * t).sin() * (y + 0.5), y))
    };
    (topo, rest, at)
}

fn woven(topo: &Topology, pos: &[DVec3]) -> Conductivity {
    Conductivity::Woven(WovenFaces {
        tensor: vec![[3e-4, 0.5e-4, 1e-4]; topo.n_faces()],
        uv: topo
            .faces()
            .iter()
            .map(|f| f.map(|v| [pos[v as usize].x + 0.5, pos[v as usize].z + 0.5]))
            .collect(),
        angle: vec![0.2; topo.n_faces()],
    })
}

/// The pour of these tests: a Gaussian blob high on the hanging sheet (in its x–z plane).
fn blob(rest: &[DVec3]) -> Vec<f64> {
    let flat: Vec<DVec3> = rest.iter().map(|p| DVec3::new(p.x, p.z, 0.0)).collect();
    gaussian(&flat, glam::DVec2::new(0.0, 0.2), 0.01, 0.5)
}

/// Runs `frames` frames of the hanging sheet at `level`, a blob poured at frame 0.
fn run(level: u32, frames: usize) -> Detailed {
    run_on(12, level, frames)
}

/// The blob cut to zero below 1e-4 of its peak (a pour with a compact support).
fn compact(blob: Vec<f64>) -> Vec<f64> {
    let peak = blob.iter().fold(0.0f64, |m, x| m.max(*x));
    blob.into_iter()
        .map(|x| if x < 1e-4 * peak { 0.0 } else { x })
        .collect()
}

/// [`run`] on a sheet of `n` × `n` quads (the pour compact above 12).
fn run_on(n: usize, level: u32, frames: usize) -> Detailed {
    let (topo, rest, at) = hanging(n);
    let conductivity = woven(&topo, &rest);
    let mut sim = Detailed::new(
        topo,
        &rest,
        &at(0.0),
        conductivity,
        params(),
        [0.5, 0.1, 0.1],
        level,
        Par::Seq,
    )
    .unwrap();
    let blob = if n > 12 {
        compact(blob(&rest))
    } else {
        blob(&rest)
    };
    sim.add_liquid(&blob, 0.05, None).unwrap();
    let dt = 1.0 / 25.0;
    for k in 1..=frames {
        sim.step(&at(k as f64 * dt), dt, Some(&at((k + 1) as f64 * dt)))
            .unwrap();
    }
    sim
}

#[test]
fn level_zero_is_the_cloth_simulator_bit_for_bit() {
    let (topo, rest, at) = hanging(12);
    let conductivity = woven(&topo, &rest);
    let mut plain = Simulator::new(
        topo.clone(),
        &rest,
        &at(0.0),
        conductivity.clone(),
        params(),
        [0.5, 0.1, 0.1],
        Par::Seq,
    )
    .unwrap();
    let blob = blob(&rest);
    plain.add_liquid(&blob, 0.05, None).unwrap();
    let dt = 1.0 / 25.0;
    for k in 1..=10 {
        plain
            .step(&at(k as f64 * dt), dt, Some(&at((k + 1) as f64 * dt)))
            .unwrap();
    }
    let d = run(0, 10);
    assert_eq!(d.level(), 0);
    let bits = |v: Vec<f64>| v.into_iter().map(f64::to_bits).collect::<Vec<_>>();
    assert_eq!(bits(d.solute_density()), bits(plain.solute_density()));
    assert_eq!(bits(d.wetness()), bits(plain.wetness()));
    assert_eq!(bits(d.deposit()), bits(plain.deposit()));
    assert_eq!(d.totals(), plain.totals());
}

#[test]
fn totals_are_exact_across_levels() {
    let (topo, rest, at) = hanging(12);
    let p0 = at(0.0);
    let area = vertex_areas(&topo, &p0);
    let blob = blob(&rest);
    let poured: f64 = blob.iter().zip(&area).map(|(s, a)| s * a).sum();
    for level in 1..=2 {
        let mut sim = Detailed::new(
            topo.clone(),
            &rest,
            &p0,
            woven(&topo, &rest),
            params(),
            [0.5, 0.1, 0.1],
            level,
            Par::Seq,
        )
        .unwrap();
        sim.add_liquid(&blob, 0.05, Some([0.1, 0.6, 0.2])).unwrap();
        let fine_total = sim.totals().solvent;
        assert!(
            (fine_total - poured).abs() <= 1e-12 * poured,
            "level {level}: poured {poured}, on the refined cloth {fine_total}"
        );
        let dt = 1.0 / 25.0;
        for k in 1..=15 {
            sim.step(&at(k as f64 * dt), dt, None).unwrap();
            // the cloth-level masses, summed, against the fine totals
            let coarse = sim.fields();
            let solute: f64 = (0..coarse.solute.len())
                .map(|i| coarse.solute[i] + coarse.absorbed_solute[i] + coarse.adsorbed[i])
                .sum();
            let t = sim.totals();
            assert!(
                (solute - t.solute).abs() <= 1e-12 * t.solute,
                "level {level}, frame {k}: cloth {solute} vs fine {}",
                t.solute
            );
            // densities read at the cloth, integrated with the cloth's areas
            let now = vertex_areas(&topo, &at(k as f64 * dt));
            let read: f64 = sim
                .solute_density()
                .iter()
                .zip(&now)
                .map(|(s, a)| s * a)
                .sum();
            assert!(
                (read - t.solute).abs() <= 1e-12 * t.solute,
                "level {level}, frame {k}"
            );
            // the colour read at the cloth is the poured one where there is solute
            for (i, c) in sim.solute_color().iter().enumerate() {
                if coarse.solute[i] > 1e-9 * t.solute {
                    for (k, want) in [0.1, 0.6, 0.2].into_iter().enumerate() {
                        assert!((c[k] - want).abs() < 1e-9, "vertex {i}: {c:?}");
                    }
                }
            }
        }
        assert_eq!(sim.wetness().len(), topo.n_vertices());
        assert_eq!(sim.velocity_world().len(), topo.n_vertices());
    }
}

#[test]
fn a_stain_converges_as_the_level_grows() {
    let frames = 12;
    let (topo, _, at) = hanging(12);
    let area = vertex_areas(&topo, &at(frames as f64 / 25.0));
    let stains: Vec<Vec<f64>> = (0..=3).map(|l| run(l, frames).solute_density()).collect();
    let l2 = |a: &[f64], b: &[f64]| -> f64 {
        a.iter()
            .zip(b)
            .zip(&area)
            .map(|((x, y), w)| w * (x - y) * (x - y))
            .sum::<f64>()
            .sqrt()
    };
    let norm = l2(&stains[3], &vec![0.0; stains[3].len()]);
    let diffs: Vec<f64> = (0..3)
        .map(|l| l2(&stains[l], &stains[l + 1]) / norm)
        .collect();
    println!("relative L2 differences between levels 0-1, 1-2, 2-3: {diffs:.4?}");
    assert!(diffs[0] > diffs[1] && diffs[1] > diffs[2], "{diffs:?}");
    // measured 0.085, 0.039, 0.030: halving the spacing halves the first difference
    assert!(diffs[1] < 0.6 * diffs[0], "{diffs:?}");
}

#[test]
fn bad_input_names_the_cloths_elements() {
    let (topo, rest, at) = hanging(6);
    let mk = |level| {
        Detailed::new(
            topo.clone(),
            &rest,
            &at(0.0),
            Conductivity::Isotropic(2e-4),
            params(),
            [0.5, 0.1, 0.1],
            level,
            Par::Seq,
        )
    };
    match mk(4) {
        Err(Error::Param(ParamError::OutOfRange { name, .. })) => assert_eq!(name, "detail level"),
        other => panic!("{other:?}"),
    }
    let mut sim = mk(2).unwrap();
    let n = topo.n_vertices();
    let mut bad = at(0.04);
    bad[17] = DVec3::new(f64::NAN, 0.0, 0.0);
    match sim.step(&bad, 0.04, None) {
        Err(Error::Mesh(MeshError::NonFinitePosition { vertex })) => assert_eq!(vertex, 17),
        other => panic!("{other:?}"),
    }
    match sim.add_liquid(&vec![0.0; n + 1], 0.05, None) {
        Err(Error::Param(ParamError::Length { expected, .. })) => assert_eq!(expected, n),
        other => panic!("{other:?}"),
    }
    let mut neg = vec![0.0; n];
    neg[5] = -1.0;
    match sim.add_liquid(&neg, 0.05, None) {
        Err(Error::Param(ParamError::OutOfRangeAt { index, .. })) => assert_eq!(index, 5),
        other => panic!("{other:?}"),
    }
    assert_eq!(sim.time(), 0.0, "nothing stepped");
}

#[test]
fn too_fine_a_mesh_is_refused_with_the_figure_before_allocating() {
    // a 1000×1000-quad grid at level 3 would make 64 M vertices: refused from the
    // counts alone
    let (topo, _) = Grid::new(1000, 0.5).build();
    match Refinement::new(&topo, 3) {
        Err(Error::Mesh(MeshError::DetailTooLarge {
            level,
            vertices,
            max,
        })) => {
            assert_eq!(level, 3);
            assert!(vertices > max, "{vertices}");
            assert_eq!(vertices, 1001 * 1001 + 3_002_000 * 7 + 2_000_000 * 21);
        }
        other => panic!("{other:?}"),
    }
}

/// The old, eager Detail: the cloth simulator on the whole refined cloth (what
/// `Detailed` builds lazily), driven as `Detailed` drives it.
fn run_whole(n: usize, level: u32, frames: usize) -> (Simulator, Refinement) {
    let (topo, rest, at) = hanging(n);
    let r = Refinement::new(&topo, level).unwrap();
    let conductivity = match woven(&topo, &rest) {
        Conductivity::Woven(w) => Conductivity::Woven(WovenFaces {
            tensor: r.face_values(&w.tensor),
            uv: r.face_uv(&w.uv),
            angle: r.face_values(&w.angle),
        }),
        c => c,
    };
    let mut sim = Simulator::new(
        r.fine().clone(),
        &r.prolong(&rest),
        &r.prolong(&at(0.0)),
        conductivity,
        params(),
        [0.5, 0.1, 0.1],
        Par::Seq,
    )
    .unwrap();
    sim.add_liquid(&r.prolong(&compact(blob(&rest))), 0.05, None)
        .unwrap();
    let dt = 1.0 / 25.0;
    for k in 1..=frames {
        let next = r.prolong(&at((k + 1) as f64 * dt));
        sim.step(&r.prolong(&at(k as f64 * dt)), dt, Some(&next))
            .unwrap();
    }
    (sim, r)
}

#[test]
fn the_lazily_built_refinement_is_the_whole_refined_cloth() {
    // level 2 on the hanging sheet: the stain runs down from the blob; the lazy part
    // covers what the liquid reached, and the stain on it is the whole refined cloth's
    // to the solvers' tolerance (sums in another order, other tangent axes)
    let frames = 8;
    let lazy = run_on(30, 2, frames);
    let (whole, r) = run_whole(30, 2, frames);
    assert_eq!(lazy.n_fine_vertices(), r.fine().n_vertices());
    assert!(
        lazy.n_built_vertices() < r.fine().n_vertices(),
        "{} of {} built",
        lazy.n_built_vertices(),
        r.fine().n_vertices()
    );
    let a = lazy.fine_solute_density();
    let b = whole.solute_density();
    let peak = b.iter().fold(0.0f64, |m, x| m.max(*x));
    let max = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    let l2 = (a
        .iter()
        .zip(&b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        / b.iter().map(|y| y * y).sum::<f64>())
    .sqrt();
    println!(
        "lazy vs whole: {} of {} fine vertices built; max |Δ| {:.2e} of the peak, relative L2 {l2:.2e}",
        lazy.n_built_vertices(),
        r.fine().n_vertices(),
        max / peak
    );
    assert!(max <= 1e-6 * peak && l2 <= 1e-6, "max {max:e}, L2 {l2:e}");
    // the totals are the same to rounding
    let (tl, tw) = (lazy.totals(), whole.totals());
    assert!((tl.solute - tw.solute).abs() <= 1e-12 * tw.solute);
    assert!((tl.solvent - tw.solvent).abs() <= 1e-9 * tw.solvent);
    // the fine read-outs are the simulator's where built and nothing elsewhere
    let wet = lazy.fine_wetness();
    let ww = whole.wetness();
    for (j, (x, y)) in wet.iter().zip(&ww).enumerate() {
        assert!(
            (x - y).abs() <= 1e-6 * peak.max(1.0),
            "fine vertex {j}: {x} vs {y}"
        );
    }
}

#[test]
fn the_same_bits_with_one_two_or_three_threads() {
    // level 2, lazily built, grown as the stain runs (growths, window builds, the shared
    // Kabsch rotations of the fine vertices inside coarse faces and on coarse edges, the
    // fine faces' shared tip angles and area vectors, the velocity extension's parallel
    // rings)
    let run_in = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                let sim = run_on(20, 2, 5);
                let bits = |v: Vec<f64>| v.into_iter().map(f64::to_bits).collect::<Vec<_>>();
                (
                    bits(sim.fine_solute_density()),
                    bits(sim.fine_wetness()),
                    sim.n_built_vertices(),
                )
            })
    };
    let one = run_in(1);
    assert!(one.0.iter().any(|&b| b != 0), "no stain");
    for threads in [2, 3] {
        assert!(run_in(threads) == one, "{threads} threads differ from one");
    }
}

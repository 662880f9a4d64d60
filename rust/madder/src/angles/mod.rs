//! # Surfaces from angles (seed ch. 3)
//!
//! A triangle mesh with fixed connectivity is described, up to a similarity (rotation,
//! translation, uniform scale), by its **corner angles** `α` (three per face) and its
//! **signed dihedral angles** `θ` (one per interior edge). This module encodes a mesh into
//! those angles ([`AngleMesh::encode`]) and reconstructs vertex positions from (possibly
//! noisy) angles ([`AngleMesh::reconstruct`], the seed's spectral method, and
//! [`AngleMesh::sequential`], the Angle-Analyzer-style baseline it is compared with).
//!
//! Decoding a sequence (the codec, issue 15), frame by frame, warm-started from the previous
//! frame's reconstruction:
//!
//! ```text
//! AngleMesh::reconstruct_warm(&self, angles: &Angles, previous: &[DVec3],
//!                             options: &ReconstructOptions) -> Result<Reconstruction, AngleError>
//! ```
//!
//! `previous` is the previous frame's decoded positions (any placement: only their shape is
//! used); the result is the cold [`AngleMesh::reconstruct`] of the same angles to the
//! iteration's tolerance (see "Warm start" below). Keep one [`AngleMesh`] for the whole
//! sequence: it keeps the connectivity-only solver work between calls.
//!
//! The fast alternative for a sequence, which the codec uses (see "Tracked reconstruction"):
//!
//! ```text
//! AngleMesh::reconstruct_tracked(&self, angles: &Angles, previous: &[DVec3],
//!                                options: &ReconstructOptions)
//!     -> Result<Option<Reconstruction>, AngleError>
//! AngleMesh::reconstruct_tracked_cold(&self, angles: &Angles, options: &ReconstructOptions)
//!     -> Result<Option<Reconstruction>, AngleError>
//! ```
//!
//! ## Conventions (§3.3)
//! Faces are counter-clockwise triples `(i, j, k)`; an interior edge `(a, b)`, `a < b`, runs
//! `a → b` in one face `t₁ = (a, b, k)` (up to rotation) and `b → a` in the other
//! `t₂ = (b, a, l)`: a mesh where both faces run it the same way is not (consistently)
//! orientable and is refused, naming the edge; so is an edge with three or more faces.
//! `α` at corner `c` of face `f` is the angle at vertex `faces[f][c]`. With `Nₜ` the
//! counter-clockwise normal of face `t` and `ê` the unit vector `a → b`,
//!
//! ```text
//! θ_ab = atan2((N₁ × N₂)·ê, N₁·N₂)   ∈ (−π, π],
//! ```
//!
//! positive where the surface is convex (bends away from its normals), 0 where flat. It does
//! not depend on which face is called `t₁`. Interior edges are listed in the topology's edge
//! order ([`AngleMesh::interior_edges`]).
//!
//! ## Preprocessing (§3.3.4)
//! Corners are clamped to `[ε, π − ε]` and dihedrals to `[−π + ε, π − ε]`, `ε = 0.02`; the
//! three corners of a face are then rescaled to sum to `π` (eq. 3.1; three angles are given,
//! so their sum is made exact instead of deriving the third: after the rescale a corner is
//! still `≥ ε/3`, as the sum is at most `3π`).
//!
//! ## Local construction and transitions (eq. 3.2, Fig. 3.1)
//! For an interior edge the four vertices are placed from the angles alone: `a = 0`,
//! `b = (1, 0, 0)`, `k` in the `xy`-plane (`y > 0`) from `t₁`'s corners at `a` and `b` (law
//! of sines), `l` from `t₂`'s corners, unfolded to `y < 0` and turned about the `x`-axis by
//! `θ`. Every face `t = (p₀, p₁, p₂)` has the non-orthonormal frame
//! `Fₜ = (p₁ − p₀, p₂ − p₀, √Aₜ nₜ)` (Fig. 3.2; the normal scaled by `√area` keeps every
//! column a length, so the relations below are scale-free). The transition of the edge is
//! `R = F̄₂⁻¹ F̄₁`, the frames of the local construction, so that eq. 3.2 reads
//! `F₁ − F₂ R = 0` and holds for *any* linear image `M F` of the frames. (The seed writes
//! `R = F̄₁ F̄₂⁻¹`, which belongs to the left-multiplied form; with eq. 3.2's right product
//! the factors go the other way.)
//!
//! ## The quadratic form (eqs. 3.2–3.3 substituted, §3.3.4)
//! Unknowns are the positions and the frames; eq. 3.3 ties the frame of `(i, j, k)` to its
//! edges: `[x_j − x_i, x_k − x_j, x_i − x_k] − F [[1, −1, 0], [0, 1, −1], [0, 0, 0]] = 0`,
//! that is, the frame's first two columns *are* the edge vectors `x_j − x_i`, `x_k − x_i`.
//! The seed penalizes eq. 3.3 in least squares beside eq. 3.2; we impose it exactly
//! instead, substituting `Fₜ = (x_{p₁} − x_{p₀}, x_{p₂} − x_{p₀}, mₜ)` into eq. 3.2: the
//! unknowns are the positions and one column `mₜ` (the scaled normal `√A n`) per face, and
//! the energy is `Σ_edges ‖F₁ − F₂R‖² = x̃ᵀ A x̃`. Why: the speed targets of issue 15. The
//! seed's form has `|V| + 3|T| ≈ 7|V|` scalar unknowns; this one `|V| + |T| ≈ 3|V|`, and
//! the Cholesky factorization (the cost) shrinks with it (ARCHITECTURE.md has the figures).
//! There is no exact smaller form: the frame unknowns couple across edges, so eliminating
//! them (a Schur complement onto the positions) gives a dense matrix. On consistent angles the kernel is the same (the true embedding satisfies
//! both equations exactly), so exact angles still reconstruct exactly; on noisy angles the
//! minimizer differs, and the noise study (seed Fig. 3.3) moves by −31 % to +9 % per
//! level, the spectral method still far ahead of the baseline (figures before/after in
//! ARCHITECTURE.md). Every equation is a row of a 3×n matrix equal to a row of another
//! times a known matrix, so the three coordinates never mix: `A = I₃ ⊗ A₁` with `A₁` of
//! size `|V| + |T|` (positions, then `mₜ` per face, of one coordinate). The 12 lowest
//! eigenvectors of `A` are therefore exactly `{qₐ ⊗ axis_r}` for the 4 lowest eigenvectors
//! `qₐ` of `A₁`: we solve the 9× smaller scalar problem. One of the four is known in
//! closed form: the translation (all positions 1, `m` 0) is in the kernel whatever the
//! angles, so it is deflated and only the 3 lowest of the rest are computed.
//!
//! ## Eigenvectors: shift-invert subspace iteration
//! faer's partial eigensolver finds the largest eigenvalues, and `A₁` is singular (exactly,
//! for consistent angles) and badly conditioned: a smooth non-affine deformation costs only
//! `O(h⁴)` relative to the largest eigenvalue (`h` the edge length), so `λ₅/λ_max ~ 1/|V|²`
//! and a Krylov method on `A₁` itself would need thousands of steps. We factor
//! `A₁ + σI` once with faer's sparse Cholesky (`σ = 10⁻¹² · mean diagonal`: a small negative
//! shift of the spectrum's origin, which makes the singular matrix positive definite yet
//! sits far below `λ₅`) and run subspace iteration with `(A₁ + σI)⁻¹` on a block of 7 (3
//! wanted + 4 guard vectors), kept orthogonal to the translation, with a Rayleigh–Ritz step
//! on `A₁` each round. The wanted vectors converge like `((λ₃' + σ)/(λ₈' + σ))ᵏ`: on
//! consistent angles `λ₃' ≈ 0` and the factor is below `σ/λ₄ ≈ 10⁻⁷` at 10k vertices,
//! `10⁻⁵` at 100k (measured `λ₄/diag` 4·10⁻⁶ and 4·10⁻⁸): a handful of triangular solves, each reusing the one
//! factorization. LOBPCG would need fewer solves on a poor shift but more code and
//! breakdown handling; with the shift this good, the plain iteration is simpler and
//! deterministic. Stopping: when the wanted subspace moves by less than `10⁻¹⁰`, or stops
//! improving (rounding floor) once below `10⁻⁸`; else an error after 200 rounds.
//!
//! ## Warm start (a sequence of frames)
//! [`AngleMesh::reconstruct_warm`] solves the same eigenproblem as the cold reconstruction,
//! with two savings. (1) The pattern of `A₁` and its symbolic Cholesky analysis (AMD
//! ordering, elimination tree, supernodes) depend on the connectivity only: the mesh keeps
//! them (a `Mutex`-guarded cache, taken out during a call and put back after, so concurrent
//! calls never share it) and each frame only assembles the values and refactorizes
//! numerically. The cold path uses the same cache, so the two differ only in the start.
//! (2) The iteration starts from the previous frame instead of random vectors: for each
//! coordinate `d`, the vector of unknowns the previous positions give (their `d`-th
//! coordinates and row `d` of each face's `mₜ`), which spans the previous frame's wanted
//! subspace exactly; one random guard vector completes the block (4 instead of the cold
//! path's 7: the start is close, so fewer guards cost fewer rounds than their triangular
//! solves; measured 6 rounds × 4 columns against 5 × 7 at 1 % noise). Any linear image
//! of the previous positions spans the same subspace, so their placement does not matter.
//! The stopping rule is unchanged, so warm and cold agree to the iteration's tolerance
//! (measured ≤ 10⁻¹² of the bounding box at 625 vertices, 2·10⁻⁹ at 100k). The numeric
//! factorization is still redone every frame: a trial that kept an earlier frame's
//! factorization as the preconditioner of a LOBPCG solve (not kept) converged only ~4× per
//! iteration with a one-frame-old factor on a 625-vertex cloth, and worse as the mesh
//! grows (the frame-to-frame change of `A₁` is fixed relative to its diagonal while `λ₄`
//! falls like `1/|V|²`), and its result depended on the call history.
//!
//! ## Affine correction by voting (§3.3.2, Algorithm 1)
//! The eigenvectors give an embedding `x_v = L q_v`, `F_t = L G_t` for an unknown linear
//! `L` (`q_v` the eigenvectors' position entries, `G_t` the frames they give:
//! `(q_{p₁} − q_{p₀}, q_{p₂} − q_{p₀}, m_t)`). First `L₀ = ±I`, the sign
//! that gives most frames a positive determinant (a mirrored embedding would flip every
//! dihedral). Then each interior edge votes: `T_e = [F̄₁ F̄₂][F₁ F₂]ᵀ([F₁ F₂][F₁ F₂]ᵀ)⁻¹`,
//! the least-squares map of the embedding's two frames onto the local construction; its
//! polar decomposition `T_e = U_e S_e` (by the 3×3 SVD of [`crate::mesh::kabsch`]) drops the
//! vote's arbitrary rotation; `S_e/‖S_e‖_F` drops its scale. `T = S/‖S‖_F` for
//! `S = Σ_e S_e/‖S_e‖_F`, and `L = T L₀`.
//!
//! ## Optional gradient descent in 12-D (§3.3.3)
//! The 12-D space of the seed is `x_v = L q_v + c` (9 + 3 coefficients); the translation
//! `c` moves no angle and the voting's `T` is itself a linear map of the same 9-D space, so
//! the block-cyclic scheme (T, then Λ) collapses to descent on `L`. The energy is
//! `E = Σ_corners (α − ᾱ)² + Σ_edges (θ − θ̄)²` against the preprocessed angles; its
//! gradient is assembled by the chain rule from the analytic derivatives of each corner
//! angle (`∂α/∂u = −w⊥/(|w⊥||u|)` for the corner's edge vectors `u`, `w`) and each dihedral
//! (the thin-shell bending gradient: `∂θ/∂x_k = −|e| N₁/|N₁|²` at the opposite vertices,
//! the edge's ends taking the balancing combination), `∂E/∂L = Σ_v g_v q_vᵀ`. Steps use an
//! Armijo backtracking line search and are taken only when `E` decreases, so the residual
//! history never increases.
//!
//! ## Rigid placement
//! Angles carry no rotation, translation or scale. A [`Placement`] (one face and its three
//! positions) keeps them: the reconstruction is mapped by the similarity (Umeyama, proper
//! rotation) that takes that face onto the stored triangle. Without one, the result has its
//! centroid at the origin and mean edge length 1.
//!
//! ## Tracked reconstruction (a frame that follows the previous one)
//! The spectral method needs a factorization of `A₁` per frame, because `A₁` is built from
//! the angles; at 100k vertices that costs seconds. A frame of a sequence starts close to
//! the previous one, and [`AngleMesh::reconstruct_tracked`] uses that to solve three
//! least-squares problems whose matrices are graph Laplacians of the connectivity alone,
//! factorized once per mesh (faer's sparse Cholesky, simplicial: see
//! [`crate::ops::PrefactoredSpd::new_simplicial`]); a frame then costs triangular solves
//! and per-edge arithmetic.
//!
//! *Face shapes.* Each face `t = (p₀, p₁, p₂)` has its own frame: `x` along `p₀ → p₁`, `z`
//! its normal. In it, with unit side `p₀p₁`, the corners alone place the triangle:
//! `p₂ − p₀ = (sin α₁/sin α₂)(cos α₀, sin α₀, 0)` (law of sines), and the side from corner
//! `k` to `k + 1` points at `φ₀ = 0`, `φ₁ = π − α₁`, `φ₂ = π + α₀`. In world space the face
//! is `s_t Q_t` times that shape, with a rotation `Q_t` and a scale `s_t`.
//!
//! *Rotations.* Across an interior edge `a → b` (run `a → b` by `t₁`, `b → a` by `t₂`) the
//! two frames share the edge's direction `ê`, and the normals differ by the dihedral:
//! `N₂ = Rot(ê, θ) N₁` (which is the encoder's `θ = atan2((N₁ × N₂)·ê, N₁·N₂)`). With `φ₁`
//! the direction of `a → b` in `t₁`'s frame and `φ₂` in `t₂`'s (its side `b → a` plus `π`),
//! `Q_t C(φ)` maps `(x, y, z)` onto `(ê, N × ê, N)` for `C(φ) = R_z(φ)`, so
//!
//! ```text
//! Q₂ = Q₁ M,    M = R_z(φ₁) R_x(θ) R_z(−φ₂).
//! ```
//!
//! Consistent angles have rotations with `E_e = Q₁ M Q₂⁻¹ = I` on every edge. From the
//! previous frame's face frames, rounds of Gauss–Newton correct them: with the increments
//! `Q_t ← exp(ω_t) Q_t` (world frame), `E_e` becomes `exp(ω₁) E_e exp(−ω₂)`, whose
//! residual is `ω₁ − ω₂ + c_e` to first order, and
//!
//! ```text
//! min Σ_e |ω₁ − ω₂ + c_e|²   ⇔   L_dual ω = b,   b_t₁ −= c_e, b_t₂ += c_e,
//! ```
//!
//! with `L_dual` the Laplacian of the dual graph (faces, one edge per interior edge; the
//! three components of `ω` are three right-hand sides). The matrix is the same every round
//! and every frame; what it leaves out (the exact Jacobian's dependence on the rotations) is
//! of the order of the residual itself, so on consistent angles the rounds converge
//! quadratically (measured updates 0.15, 1.5·10⁻³, 3·10⁻⁷, 10⁻¹⁵ rad on the bench's cloth
//! at 25 frames a second) and on noisy ones linearly at a rate of the order of the noise.
//! Two cheap forms that change nothing at the fixed point: the residual is
//! `c_e = 2 sin(φ/2) n̂` (twice the vector part of the quaternion `E_e`; it vanishes where
//! the rotation vector `φ n̂` does and agrees with it to first order) and the update is the
//! normalized `(1, ω/2) Q_t` (a turn by `2 atan(|ω|/2)`, `|ω|` to second order): no
//! transcendental per round. A round that turned no face by more than `10⁻⁴` rad ends
//! the rounds (what is left, by the quadratic convergence, is ~0.1 δ² ≈ 10⁻⁹; on
//! quantized angles, which converge linearly at a rate of the order of the noise, about
//! 10⁻⁴ of the quantization error; the codec
//! starts from the previous two frames extrapolated, which leaves 10⁻² rad for the first
//! round and makes two rounds the rule). With a tolerance
//! ([`ReconstructOptions::tolerance`]) the rounds also stop once the next is predicted to
//! move less than it (`0.1 δ²` after a round of `δ`, while the convergence is
//! quadratic): the codec gives a twentieth of its quantization step, which makes one round
//! the rule for its frames. A fit that settles
//! with some edge still turned by more than 1 rad is a wrong fixed point of a start too
//! far from the angles, and is refused (`None`), as is one that has not settled after 24
//! rounds; the caller then uses the spectral method.
//!
//! *Cold start.* Without a previous frame ([`AngleMesh::reconstruct_tracked_cold`]) the
//! rotations start from `Q₀ = I` composed along a breadth-first spanning tree of the dual
//! graph, `Q₂ = Q₁ M` across each tree edge (the tree is kept with the factorizations).
//! Exact angles make that start exact; on noisy ones its rotations drift from the fit by
//! the rounding accumulated along the tree (a random walk: about `√(depth)` times an
//! angle's error), which on quantized angles is the size of a frame's motion, so the
//! rounds settle as they do for a frame (measured: the same fit the spectral start
//! reaches, to 10⁻⁸ relative). Unlike the sequential baseline below it composes rotations
//! only (no positions, so no normal is taken from accumulated positions) and it is not the
//! answer but a start for the least-squares rounds.
//!
//! *Scales.* The edge has length `ℓ₁ = sin α_{c₁}/sin α₂` in `t₁`'s unit-side shape (the
//! side opposite corner `c` has length `sin α_c / sin α₂`) and `ℓ₂` in `t₂`'s, so
//! `log s₁ + log ℓ₁ = log s₂ + log ℓ₂`: the same least-squares problem for `log s`, one more
//! right-hand side of the first round's solve.
//!
//! *Positions.* With the rotations and scales, every face side `i → j` has a target vector
//! `s_t Q_t (P_j − P_i)`, and `min Σ_t Σ_sides |x_j − x_i − s_t Q_t (P_j − P_i)|²` is one
//! solve with the vertex graph's Laplacian (an interior edge counted twice, once per face).
//! Both Laplacians are singular (constants); one `+1` on the first node's diagonal anchors
//! face 0's rotation and scale and vertex 0's position, which the similarity fixes anyway
//! (the placement, or centroid 0 and mean edge 1, as for the spectral method).
//!
//! Exact angles give the exact shape, whatever the start the rounds settle from (tested
//! from bent, mirrored and collinear starts). On noisy angles the result is a least-squares
//! fit of rotations, then scales, then positions, not the spectral method's minimizer of
//! `x̃ᵀAx̃`; on quantized angles it is the closer of the two to the truth (measured on the
//! fixtures' cloth, ARCHITECTURE.md), on closed meshes with 10 % dihedral noise within 20 %.
//!
//! ## Sequential baseline
//! [`AngleMesh::sequential`] places the seed face from its corners and walks the dual graph
//! breadth-first, placing each new face's third vertex from the placed neighbour's normal,
//! the dihedral and the new face's corners (the construction of Fig. 3.1 in world
//! coordinates); a vertex already placed is kept. Noise accumulates along the walk, which is
//! what the spectral method avoids.
//!
//! Determinism: parallel loops write disjoint outputs and every sum runs in a fixed order;
//! the Cholesky factorization and solves run sequentially (the tracked solves in two fixed
//! groups of columns, one rayon task each), so the result is bit-identical whatever the
//! number of threads.

mod cache;
pub mod codec;
mod encode;
mod local;
mod place;
mod refine;
mod sequential;
mod spectral;
mod track;

pub use codec::{CodecOptions, CodecStats, MotionDecoder, MotionEncoder};
pub use encode::{AngleMesh, Angles};
pub use local::EPS;
pub use place::Placement;
pub use spectral::{ReconstructOptions, Reconstruction};

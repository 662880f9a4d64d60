//! # A motion codec for cloth from angles (seed ch. 3, §3.1's proposed use)
//!
//! A cloth sequence with fixed connectivity is stored as the angles of §3.3 (corner angles
//! `α`, signed dihedrals `θ`, the conventions of [`crate::angles`]) plus, per frame, the
//! similarity the angles do not carry. Decoding is the reconstruction from angles (the
//! tracked one, started at keyframes from rotations composed along a tree of the faces:
//! below) followed by that similarity.
//!
//! ## Quantization and closed-loop temporal prediction
//! Every angle is quantized on a uniform grid of step `Δ = 2π / 2^b` (`b` = `bits` for the
//! dihedrals, `corner_bits` for the corners): the index `q = round(a/Δ)`, wrapped to
//! `[−2^(b−1), 2^(b−1))` (a dihedral lives on the circle, so wrapping is exact; a corner
//! index is in `[0, 2^(b−2)]` and never wraps). The stored residual is `q_k − P` with the
//! prediction `P = q_{k−1}` (order 1) or `2q_{k−1} − q_{k−2}` (order 2, constant angular
//! velocity), wrapped the same way; the encoder picks the order per stream and frame, by
//! the coded size. Prediction runs on the *indices the decoder has*, so the loop is closed:
//! each angle's error is its own rounding, `≤ Δ/2`, at every frame, and never drifts (an
//! open loop predicting from the exact previous angle would add up the rounding errors).
//! Corners are sent every frame (`corners = every`) or only in frame 0 (`once`): on a
//! near-isometric cloth the corners hardly move and, sent once, cost nothing afterwards;
//! their change then becomes reconstruction error (measured in ARCHITECTURE.md).
//!
//! ## Entropy coding
//! The residuals of a stream (all corners, or all dihedrals, of one frame) are coded with a
//! two-sided geometric model fitted per stream and the range coder of `constriction`
//! (module `entropy`: why that model and that crate).
//!
//! ## Placement (closed loop too)
//! The decoder reconstructs the normalized shape `y` (centroid 0, mean edge 1). The encoder
//! runs the same reconstruction on the same quantized angles — bit-identical, as the
//! reconstruction is deterministic — and fits the similarity `x ≈ sRy + t` to the true
//! positions over *all* vertices (Umeyama, least squares). A reference triangle (the
//! [`crate::angles::Placement`] of a decoded mesh) would pin one face exactly and let the
//! angle error grow with the distance from it; the fit spreads it instead and lowers both
//! RMS and maximum error. Stored as 8 `f32` (scale, unit quaternion, translation).
//!
//! ## Warm-started decoding, keyframes
//! Frame `k` is decoded by the tracked reconstruction ([`AngleMesh::reconstruct_tracked`](crate::angles::AngleMesh::reconstruct_tracked),
//! header flag 2, the default) started from frame `k − 1`'s normalized reconstruction,
//! extrapolated linearly with frame `k − 2`'s (`2y_{k−1} − y_{k−2}`) when neither `k` nor
//! `k − 1` is a keyframe (a keyframe's decode is placed differently from the frame before
//! it): the start is then ~10⁻² rad from the answer instead of a frame's turn, and the
//! rotations settle in two rounds instead of three, and in one where the rounds may stop a
//! twentieth of the finer quantization step short of settling (files of flag 4: the
//! angles carry `Δ/2` of rounding anyway; [`ReconstructOptions::tolerance`](crate::angles::ReconstructOptions::tolerance));
//! at a keyframe (`k` a multiple of the keyframe interval `K`, stored in the header; 0 =
//! every frame) it is started without a previous frame, from the transition rotations
//! composed along a spanning tree of the faces ([`AngleMesh::reconstruct_tracked_cold`](crate::angles::AngleMesh::reconstruct_tracked_cold),
//! header flag 4, which this version's encoder sets with flag 2): on quantized angles that
//! start drifts from the fit by the accumulated rounding, which the rounds remove as they
//! remove a frame's motion, and it reaches the fit the spectral start reaches (to 10⁻⁸
//! of the diagonal, `tests/angles_tracked.rs`) for the cost of a warm frame instead of an
//! eigen-solve (100k vertices: 0.15 s against 4.5 s). Every frame is then the same kind
//! of fit: a rigid motion, whose angles never change, decodes to one shape moved
//! rigidly. Where those rounds do not settle (noisy angles), the spectral reconstruction
//! starts them instead, and where that does not settle either it is used itself; a warm
//! frame that does not settle falls back to the warm spectral reconstruction. Files of
//! flag 2 without flag 4 (written before flag 4 existed) start their keyframes from the
//! spectral reconstruction, as they were encoded: each start fixes face 0's frame, so the
//! two are the same fit turned otherwise, and a file is decoded by its own rule.
//! Files written with the flag off decode every warm frame by the warm-started spectral
//! reconstruction ([`AngleMesh::reconstruct_warm`](crate::angles::AngleMesh::reconstruct_warm)), as version 1 did before the flag
//! existed. Neither agrees with a cold decode bit for bit, so the encoder runs the very
//! same chain as the decoder (its placement fit and its error figures are then those of
//! the decoder's output, bit for bit). A sequential read costs one tracked reconstruction;
//! a jump to frame `k` replays the entropy streams and reconstructs from the keyframe
//! `K⌊k/K⌋` on (at most `K` reconstructions).
//!
//! ## How angle errors become position errors
//! An angle error is a local bend or shear; the spectral solve spreads its inconsistency
//! over the whole mesh in least squares (that is why it beats the sequential walk), but a
//! systematic error (the same rounding on a row of edges) integrates along the cloth like
//! a bent hinge: position error grows with the distance over which it acts. With `Δ/2`
//! uniform rounding on `~3|V|` dihedrals and `~6|V|` corners the RMS position error is a
//! fixed multiple of `Δ` for a given mesh (measured, ARCHITECTURE.md); the maximum is a few
//! times the RMS, at the free corners of an open cloth.
//!
//! ## File format (`.madm`, little-endian)
//! ```text
//! header  magic "MADDERMO" | version u32 | n_points u32 | n_faces u32 | n_frames u32
//!         | start f64 | rate f64 | bits u8 | corner_bits u8 | flags u8 (1: corners once,
//!         2: warm frames tracked, 4: keyframes from the tree, only with 2)
//!         | keyframe interval u8 | crc32 u32 (of the 44 bytes before it and the faces)
//! faces   n_faces × 3 u32
//! frame*  payload length u32 | crc32 u32 of the payload | payload
//! payload placement 8 f32 | [corner stream] | dihedral stream
//! stream  predictor order u8 | the entropy-coded residuals (module `entropy`)
//! ```
//! The encoder writes to a temporary file next to the target and renames it into place
//! only in [`MotionEncoder::finish`]; an aborted or dropped encoder removes it.
//!
//! ## Fuzzing
//! `rust/madder/fuzz`, target `madm` (seeds in `seeds/madm`: two small files, checksums
//! repaired or raw). Run on 2026-11-26 for 150 s (AddressSanitizer, 2 shared cores):
//! 60,404 inputs, no crash, no leak, no allocation over libFuzzer's 2 GiB limit; coverage
//! grew from 3,183 to 3,884 edges (corpus of 628 inputs). The reader's bad-file paths are
//! also covered by `tests/angles_codec.rs`.

mod baseline;
mod decoder;
mod encoder;
mod entropy;
mod format;
mod frame;
mod quant;

pub use baseline::{BaselineStats, position_baseline};
pub use decoder::MotionDecoder;
pub use encoder::{CodecOptions, CodecStats, MotionEncoder};
pub use format::VERSION;

//! The position baselines the angle codec is measured against (same run, same entropy
//! coder): positions quantized on the sequence's bounding cube with `b` bits per
//! coordinate, then either stored raw (`b` bits each) or coded as temporal residuals
//! (order 1 or 2, the better per axis and frame, as for the angles) with the range coder of
//! module `entropy`. Errors are measured on the dequantized positions, over the bounding-box
//! diagonal of the sequence, like [`super::CodecStats`].

use glam::DVec3;

use super::entropy;

/// What a baseline costs and how accurate it is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BaselineStats {
    /// Bits per vertex per frame (payload; the baselines carry no connectivity).
    pub bits_per_vertex_frame: f64,
    /// Largest vertex error over the bounding-box diagonal.
    pub max_error: f64,
    /// RMS vertex error over the bounding-box diagonal.
    pub rms_error: f64,
}

/// Quantizes `frames` (each the same length, all finite) with `bits` bits per coordinate
/// on the bounding cube; `predict`: temporal prediction + range coding, else raw.
///
/// # Panics
/// If `frames` is empty, the frames differ in length or `bits` is not in 1..=24 (a
/// benchmark helper: the callers check their input).
pub fn position_baseline(frames: &[Vec<DVec3>], bits: u32, predict: bool) -> BaselineStats {
    assert!(!frames.is_empty() && (1..=24).contains(&bits));
    let n = frames[0].len();
    assert!(frames.iter().all(|f| f.len() == n));
    let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for p in frames.iter().flatten() {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    let diagonal = (hi - lo).length().max(f64::MIN_POSITIVE);
    let side = (hi - lo).max_element().max(f64::MIN_POSITIVE);
    let levels = ((1u64 << bits) - 1) as f64;
    let h = side / levels;
    let (mut max_abs, mut sum_sq) = (0.0f64, 0.0f64);
    let mut coded_bytes = 0usize;
    let mut prev: Option<Vec<[i64; 3]>> = None;
    let mut prev2: Option<Vec<[i64; 3]>> = None;
    for f in frames {
        let q: Vec<[i64; 3]> = f
            .iter()
            .map(|p| {
                let r = (*p - lo) / h;
                [r.x.round() as i64, r.y.round() as i64, r.z.round() as i64]
            })
            .collect();
        for (p, qi) in f.iter().zip(&q) {
            let back = lo + DVec3::new(qi[0] as f64, qi[1] as f64, qi[2] as f64) * h;
            let d = (*p - back).length();
            max_abs = max_abs.max(d);
            sum_sq += d * d;
        }
        if predict {
            for axis in 0..3 {
                let mut best = usize::MAX;
                let orders: &[u8] = match (&prev, &prev2) {
                    (Some(_), Some(_)) => &[1, 2],
                    (Some(_), None) => &[1],
                    _ => &[0],
                };
                for &order in orders {
                    let r: Vec<i32> = (0..n)
                        .map(|i| {
                            let pred = match (order, &prev, &prev2) {
                                (2, Some(a), Some(b)) => 2 * a[i][axis] - b[i][axis],
                                (1 | 2, Some(a), _) => a[i][axis],
                                _ => 0,
                            };
                            (q[i][axis] - pred) as i32
                        })
                        .collect();
                    let mut buf = vec![order];
                    entropy::encode(&r, &mut buf);
                    best = best.min(buf.len());
                }
                coded_bytes += best;
            }
            // the frame's 4-byte length, as a file would need
            coded_bytes += 4;
        }
        prev2 = prev.take();
        prev = Some(q);
    }
    let nf = (n * frames.len()) as f64;
    let bits_per_vertex_frame = if predict {
        8.0 * coded_bytes as f64 / nf
    } else {
        3.0 * bits as f64
    };
    BaselineStats {
        bits_per_vertex_frame,
        max_error: max_abs / diagonal,
        rms_error: (sum_sq / nf).sqrt() / diagonal,
    }
}

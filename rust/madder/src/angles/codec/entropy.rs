//! Entropy coding of integer residuals: a two-sided geometric model `p(r) ∝ ρ^|r|` on
//! `−K..=K` plus an escape symbol, fitted per stream and per frame (only `K`, `ρ` and the
//! escape count are stored), and `constriction`'s range coder.
//!
//! Why this model: temporal residuals of quantized angles and positions are sharply peaked
//! at 0 with roughly exponential tails (a quantized Laplacian), so one parameter describes
//! them; storing it costs 14 bytes per stream and frame instead of a histogram. Why
//! `constriction` (0.5.0, pinned): a maintained crate with a range coder that is within a
//! fraction of a percent of the model's entropy and accepts an explicit categorical model
//! of any alphabet size. Its queue-based range coder decodes in encoding order, which a
//! streaming reader wants (the ANS stack coder decodes in reverse).
//!
//! Determinism: the model's probabilities are `ρ^|r|` computed by repeated multiplication
//! (no `exp`/`pow`, so no libm differences between platforms) and quantized to fixed point
//! by `constriction`'s `from_floating_point_probabilities_fast`, plain IEEE arithmetic: the
//! encoder and any decoder build bit-identical models from the stored `ρ`.

use constriction::stream::model::DefaultContiguousCategoricalEntropyModel;
use constriction::stream::queue::{DefaultRangeDecoder, DefaultRangeEncoder};
use constriction::stream::{Decode, Encode};

/// Largest `|r|` coded by the model; larger residuals are escaped and stored as `i32`.
const K_MAX: i32 = 2048;

/// The candidate values of `ρ`: `1 − 2^(−j/4)`, j = 1..=80, and a near-zero one.
fn rho_candidates() -> impl Iterator<Item = f64> {
    std::iter::once(1e-6).chain((1..=80).map(|j| 1.0 - (-(j as f64) / 4.0).exp2()))
}

/// The model's probabilities: `ρ^|r|` for `r = −K..=K`, then the escape weight.
fn probabilities(k: i32, rho: f64, n: usize, n_esc: usize) -> Vec<f64> {
    let k = k as usize;
    let mut pos = Vec::with_capacity(k + 1);
    let mut p = 1.0f64;
    for _ in 0..=k {
        pos.push(p);
        p *= rho;
    }
    let mut probs = Vec::with_capacity(2 * k + 2);
    probs.extend(pos.iter().rev());
    probs.extend(&pos[1..]);
    let total: f64 = probs.iter().sum();
    let esc = if n_esc == 0 {
        0.0
    } else if n_esc >= n {
        total
    } else {
        total * n_esc as f64 / (n - n_esc) as f64
    };
    probs.push(esc);
    probs
}

/// Appends the coded `residuals` to `out`: `K` (u16), `ρ` (f64), the escape count (u32)
/// and the escaped values (i32), the number of 32-bit words (u32) and the words.
pub(crate) fn encode(residuals: &[i32], out: &mut Vec<u8>) {
    let n = residuals.len();
    let k = residuals
        .iter()
        .map(|r| r.unsigned_abs().min(K_MAX as u32 + 1) as i32)
        .filter(|&a| a <= K_MAX)
        .max()
        .unwrap_or(0);
    let escapes: Vec<i32> = residuals
        .iter()
        .copied()
        .filter(|r| r.unsigned_abs() > k as u32)
        .collect();
    // histogram of |r| for the fit
    let mut hist = vec![0usize; k as usize + 1];
    for r in residuals {
        if r.unsigned_abs() <= k as u32 {
            hist[r.unsigned_abs() as usize] += 1;
        }
    }
    let mut best = (f64::INFINITY, 0.5);
    for rho in rho_candidates() {
        // −log₂ of the normalized two-sided geometric on −K..=K
        let mut z = 1.0;
        let mut p = 1.0;
        for _ in 0..k {
            p *= rho;
            z += 2.0 * p;
        }
        let cost: f64 = hist
            .iter()
            .enumerate()
            .filter(|&(_, &c)| c > 0)
            .map(|(a, &c)| c as f64 * ((z).log2() - a as f64 * rho.log2()))
            .sum();
        if cost < best.0 {
            best = (cost, rho);
        }
    }
    let rho = best.1;
    out.extend_from_slice(&(k as u16).to_le_bytes());
    out.extend_from_slice(&rho.to_le_bytes());
    out.extend_from_slice(&(escapes.len() as u32).to_le_bytes());
    for e in &escapes {
        out.extend_from_slice(&e.to_le_bytes());
    }
    let probs = probabilities(k, rho, n, escapes.len());
    let model = DefaultContiguousCategoricalEntropyModel::from_floating_point_probabilities_fast(
        &probs, None,
    )
    .expect("a finite positive model with at least two symbols");
    let esc_symbol = 2 * k as usize + 1;
    let mut coder = DefaultRangeEncoder::new();
    coder
        .encode_iid_symbols(
            residuals.iter().map(|&r| {
                if r.unsigned_abs() > k as u32 {
                    esc_symbol
                } else {
                    (r + k) as usize
                }
            }),
            &model,
        )
        .expect("every symbol is in the model's alphabet");
    let words = coder.into_compressed().expect("Vec backend cannot fail");
    out.extend_from_slice(&(words.len() as u32).to_le_bytes());
    for w in &words {
        out.extend_from_slice(&w.to_le_bytes());
    }
}

/// A cursor over a frame's payload; every read past the end is an error.
pub(crate) struct Bytes<'a> {
    data: &'a [u8],
    at: usize,
}

impl<'a> Bytes<'a> {
    pub(crate) fn new(data: &'a [u8]) -> Self {
        Self { data, at: 0 }
    }
    pub(crate) fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.data.len());
        match end {
            Some(end) => {
                let s = &self.data[self.at..end];
                self.at = end;
                Ok(s)
            }
            None => Err(format!(
                "the payload ends at byte {} but {} more bytes were expected",
                self.data.len(),
                n
            )),
        }
    }
    pub(crate) fn u8(&mut self) -> Result<u8, String> {
        Ok(self.take(1)?[0])
    }
    pub(crate) fn u16(&mut self) -> Result<u16, String> {
        Ok(u16::from_le_bytes(
            self.take(2)?.try_into().unwrap_or([0; 2]),
        ))
    }
    pub(crate) fn u32(&mut self) -> Result<u32, String> {
        Ok(u32::from_le_bytes(
            self.take(4)?.try_into().unwrap_or([0; 4]),
        ))
    }
    pub(crate) fn i32(&mut self) -> Result<i32, String> {
        Ok(i32::from_le_bytes(
            self.take(4)?.try_into().unwrap_or([0; 4]),
        ))
    }
    pub(crate) fn f32(&mut self) -> Result<f32, String> {
        Ok(f32::from_le_bytes(
            self.take(4)?.try_into().unwrap_or([0; 4]),
        ))
    }
    pub(crate) fn f64(&mut self) -> Result<f64, String> {
        Ok(f64::from_le_bytes(
            self.take(8)?.try_into().unwrap_or([0; 8]),
        ))
    }
    pub(crate) fn is_empty(&self) -> bool {
        self.at == self.data.len()
    }
}

/// One stream's coded residuals, parsed but not yet decoded: [`parse`] only reads the
/// header and finds the end of the words, so the streams of a frame can be decoded side by
/// side ([`Coded::decode`]).
pub(crate) struct Coded<'a> {
    n: usize,
    k: i32,
    rho: f64,
    escapes: Vec<i32>,
    raw: &'a [u8],
}

/// Reads the header of `n` residuals written by [`encode`] and skips their words. Errors
/// (never panics) on a malformed header.
pub(crate) fn parse<'a>(bytes: &mut Bytes<'a>, n: usize) -> Result<Coded<'a>, String> {
    let k = bytes.u16()? as i32;
    if k > K_MAX {
        return Err(format!("residual range {k} exceeds {K_MAX}"));
    }
    let rho = bytes.f64()?;
    if !(rho > 0.0 && rho < 1.0) {
        return Err(format!("model parameter {rho} is not in (0, 1)"));
    }
    let n_esc = bytes.u32()? as usize;
    if n_esc > n {
        return Err(format!("{n_esc} escaped values for {n} residuals"));
    }
    let mut escapes = Vec::with_capacity(n_esc);
    for _ in 0..n_esc {
        let e = bytes.i32()?;
        if e.unsigned_abs() <= k as u32 {
            return Err(format!("escaped value {e} is inside the model's range"));
        }
        escapes.push(e);
    }
    let n_words = bytes.u32()? as usize;
    let raw = bytes.take(n_words.checked_mul(4).ok_or("word count overflows")?)?;
    Ok(Coded {
        n,
        k,
        rho,
        escapes,
        raw,
    })
}

impl Coded<'_> {
    /// The residuals. Errors (never panics) on a malformed stream.
    pub(crate) fn decode(self) -> Result<Vec<i32>, String> {
        let Self {
            n,
            k,
            rho,
            escapes,
            raw,
        } = self;
        let n_esc = escapes.len();
        if n_esc == n && n > 0 {
            // every residual escaped: the model has no mass for the others
            return Ok(escapes);
        }
        let words: Vec<u32> = raw
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        let probs = probabilities(k, rho, n, n_esc);
        let model =
            DefaultContiguousCategoricalEntropyModel::from_floating_point_probabilities_fast(
                &probs, None,
            )
            .map_err(|()| "the stored model is degenerate".to_string())?;
        let mut decoder = DefaultRangeDecoder::from_compressed(words)
            .map_err(|_| "the coded stream is malformed".to_string())?;
        let esc_symbol = 2 * k as usize + 1;
        let mut out = Vec::with_capacity(n);
        let mut esc = escapes.into_iter();
        for _ in 0..n {
            let s = decoder
                .decode_symbol(&model)
                .map_err(|_| "the coded stream is malformed".to_string())?;
            if s == esc_symbol {
                out.push(esc.next().ok_or("more escapes coded than stored")?);
            } else {
                out.push(s as i32 - k);
            }
        }
        if esc.next().is_some() {
            return Err("fewer escapes coded than stored".into());
        }
        Ok(out)
    }
}

/// Reads `n` residuals written by [`encode`]. Errors (never panics) on a malformed stream.
#[cfg(test)]
fn decode(bytes: &mut Bytes<'_>, n: usize) -> Result<Vec<i32>, String> {
    parse(bytes, n)?.decode()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_with_escapes() {
        let mut r: Vec<i32> = (0..5000).map(|i| ((i * 7919) % 13) - 6).collect();
        r[17] = 100_000;
        r[4000] = -3_000_000;
        let mut out = Vec::new();
        encode(&r, &mut out);
        let mut b = Bytes::new(&out);
        assert_eq!(decode(&mut b, r.len()).unwrap(), r);
        assert!(b.is_empty());
    }

    #[test]
    fn zeros_cost_almost_nothing() {
        let r = vec![0i32; 10_000];
        let mut out = Vec::new();
        encode(&r, &mut out);
        assert!(out.len() < 64, "{} bytes", out.len());
        assert_eq!(decode(&mut Bytes::new(&out), r.len()).unwrap(), r);
    }
}

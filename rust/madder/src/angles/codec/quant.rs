//! Quantization of the angles and closed-loop temporal prediction of their indices, and
//! the per-stream coding of the residuals (module doc, "Quantization and closed-loop
//! temporal prediction").

use super::entropy;

/// The angle-index state both sides keep: the two previous frames' indices.
#[derive(Debug, Clone, Default)]
pub(super) struct History {
    pub(super) prev: Option<Vec<i64>>,
    pub(super) prev2: Option<Vec<i64>>,
}

impl History {
    pub(super) fn push(&mut self, q: Vec<i64>) {
        self.prev2 = self.prev.take();
        self.prev = Some(q);
    }
    /// The prediction of order `order` for index `i`.
    pub(super) fn predict(&self, order: u8, i: usize) -> i64 {
        match (order, &self.prev, &self.prev2) {
            (2, Some(a), Some(b)) => 2 * a[i] - b[i],
            (1 | 2, Some(a), _) => a[i],
            _ => 0,
        }
    }
    pub(super) fn orders(&self) -> &'static [u8] {
        match (&self.prev, &self.prev2) {
            (Some(_), Some(_)) => &[1, 2],
            (Some(_), None) => &[1],
            _ => &[0],
        }
    }
}

/// Wraps an index difference into `[−2^(b−1), 2^(b−1))`.
pub(super) fn wrap(x: i64, bits: u32) -> i64 {
    let m = 1i64 << bits;
    (x + m / 2).rem_euclid(m) - m / 2
}

pub(super) fn step(bits: u32) -> f64 {
    std::f64::consts::TAU / (1u64 << bits) as f64
}

pub(super) fn quantize(a: f64, bits: u32) -> i64 {
    wrap((a / step(bits)).round() as i64, bits)
}

/// Encodes one stream's indices against `history` (the best predictor order) into `out`.
pub(super) fn encode_stream(q: &[i64], history: &History, bits: u32, out: &mut Vec<u8>) {
    let mut best: Option<Vec<u8>> = None;
    for &order in history.orders() {
        let r: Vec<i32> = q
            .iter()
            .enumerate()
            .map(|(i, &x)| wrap(x - history.predict(order, i), bits) as i32)
            .collect();
        let mut buf = vec![order];
        entropy::encode(&r, &mut buf);
        if best.as_ref().is_none_or(|b| buf.len() < b.len()) {
            best = Some(buf);
        }
    }
    out.extend(best.unwrap_or_default());
}

/// One stream of a frame, parsed: its predictor order and its coded residuals.
pub(super) struct Stream<'a> {
    pub(super) order: u8,
    pub(super) coded: entropy::Coded<'a>,
}

/// Reads one stream's header (the words are decoded later, [`Stream::indices`]).
pub(super) fn parse_stream<'a>(
    bytes: &mut entropy::Bytes<'a>,
    n: usize,
    history: &History,
) -> Result<Stream<'a>, String> {
    let order = bytes.u8()?;
    if !history.orders().contains(&order) {
        return Err(format!("predictor order {order} is not valid here"));
    }
    Ok(Stream {
        order,
        coded: entropy::parse(bytes, n)?,
    })
}

impl Stream<'_> {
    /// The quantization indices: the residuals decoded and added to the prediction.
    pub(super) fn indices(self, history: &History, bits: u32) -> Result<Vec<i64>, String> {
        let r = self.coded.decode()?;
        let half = 1i64 << (bits - 1);
        if let Some(x) = r.iter().find(|&&x| (x as i64) < -half || x as i64 >= half) {
            return Err(format!("residual {x} is outside the {bits}-bit range"));
        }
        Ok(r.iter()
            .enumerate()
            .map(|(i, &x)| wrap(x as i64 + history.predict(self.order, i), bits))
            .collect())
    }
}

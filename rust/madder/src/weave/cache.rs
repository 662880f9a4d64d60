//! Memoized homogenization. A bake (and every redraw of the add-on's panel) asks for the
//! effective tensor of the same few fabrics again and again; a solve takes tens of
//! milliseconds, a lookup microseconds.
//!
//! The key is a 128-bit hash (two independently salted SipHash-1-3 passes of the standard
//! library's fixed-key hasher) of the options that change the result (`method`,
//! `max_cells`, `reduce` — not `parallel`, which changes no bit) and of the tile *after*
//! reduction, so the same medium drawn at another size or shifted by whole cells hits the
//! same entry. The reduction merges only square blocks, so tiles with the same reduced
//! tile are the same medium up to a uniform change of scale, which leaves the effective
//! tensor unchanged; a medium of `2 × 1` rectangles keeps its own entry, apart from the
//! squares it was once conflated with (module doc of [`super::homogenize`](mod@super::homogenize)). Tensors are
//! hashed by their bits (`-0.0` folded into `0.0`). Storing hashes
//! rather than whole tiles keeps an entry at 40 bytes whatever the tile size; with 128 bits
//! an accidental collision needs on the order of 2⁶⁴ distinct tiles.
//!
//! [`HomogenizationCache`] is a plain value (one per simulator, say); [`homogenize_cached`]
//! uses a process-wide one behind a mutex. Both evict the oldest entry beyond their
//! capacity. Errors are not cached.

use std::collections::{HashMap, VecDeque};
use std::hash::{DefaultHasher, Hash, Hasher};
use std::sync::{Mutex, OnceLock};

use super::Tensor2;
use super::check::check_cells;
use super::homogenize::{HomogenizeOptions, bits, homogenize_with, reduce_checked};
use crate::error::WeaveError;

/// A bounded map from tile content (hashed) to its effective tensor.
#[derive(Debug, Clone)]
pub struct HomogenizationCache {
    map: HashMap<u128, Tensor2>,
    order: VecDeque<u128>,
    capacity: usize,
    hits: u64,
    misses: u64,
}

impl Default for HomogenizationCache {
    fn default() -> Self {
        Self::new(64)
    }
}

impl HomogenizationCache {
    /// A cache holding at most `capacity` (≥ 1) results.
    pub fn new(capacity: usize) -> Self {
        HomogenizationCache {
            map: HashMap::new(),
            order: VecDeque::new(),
            capacity: capacity.max(1),
            hits: 0,
            misses: 0,
        }
    }

    /// [`super::homogenize()`], memoized.
    pub fn homogenize(
        &mut self,
        width: usize,
        height: usize,
        tensors: &[Tensor2],
    ) -> Result<Tensor2, WeaveError> {
        self.homogenize_with(width, height, tensors, &HomogenizeOptions::default())
    }

    /// [`super::homogenize_with`], memoized.
    pub fn homogenize_with(
        &mut self,
        width: usize,
        height: usize,
        tensors: &[Tensor2],
        opts: &HomogenizeOptions,
    ) -> Result<Tensor2, WeaveError> {
        let key = key(width, height, tensors, opts)?;
        if let Some(t) = self.get(key) {
            return Ok(t);
        }
        let t = homogenize_with(width, height, tensors, opts)?;
        self.insert(key, t);
        Ok(t)
    }

    fn get(&mut self, key: u128) -> Option<Tensor2> {
        let t = self.map.get(&key).copied();
        if t.is_some() {
            self.hits += 1;
        } else {
            self.misses += 1;
        }
        t
    }

    fn insert(&mut self, key: u128, t: Tensor2) {
        if self.map.insert(key, t).is_none() {
            self.order.push_back(key);
            while self.order.len() > self.capacity {
                let old = self.order.pop_front().unwrap();
                self.map.remove(&old);
            }
        }
    }

    /// Tiles whose tensor the cache holds.
    pub fn len(&self) -> usize {
        self.map.len()
    }

    /// Whether the cache holds no tile.
    pub fn is_empty(&self) -> bool {
        self.map.is_empty()
    }

    /// Lookups answered from the cache.
    pub fn hits(&self) -> u64 {
        self.hits
    }

    /// Lookups that had to solve (including ones that then failed).
    pub fn misses(&self) -> u64 {
        self.misses
    }
}

/// The cache key of a tile under `opts` (checks the cells first, so a bad tile is reported
/// the same way as by [`super::homogenize()`]; the contrast is checked by the solve, and
/// errors are not cached).
pub(crate) fn key(
    width: usize,
    height: usize,
    tensors: &[Tensor2],
    opts: &HomogenizeOptions,
) -> Result<u128, WeaveError> {
    check_cells(width, height, tensors)?;
    let reduced;
    let (w, h, t) = if opts.reduce {
        reduced = reduce_checked(width, height, tensors);
        (reduced.0, reduced.1, &reduced.2[..])
    } else {
        (width, height, tensors)
    };
    let hash = |salt: u64| {
        let mut s = DefaultHasher::new();
        salt.hash(&mut s);
        (opts.method, opts.max_cells, opts.reduce, w, h).hash(&mut s);
        for &v in t {
            bits(v).hash(&mut s);
        }
        s.finish()
    };
    Ok(((hash(0x6d61_6464_6572) as u128) << 64) | hash(0x0077_6561_7665) as u128)
}

/// [`super::homogenize()`] through a process-wide [`HomogenizationCache`] (capacity 64). The
/// solve runs outside the lock, so concurrent callers do not wait on each other's solves.
pub fn homogenize_cached(
    width: usize,
    height: usize,
    tensors: &[Tensor2],
) -> Result<Tensor2, WeaveError> {
    static CACHE: OnceLock<Mutex<HomogenizationCache>> = OnceLock::new();
    let cache = CACHE.get_or_init(Default::default);
    let lock = || cache.lock().unwrap_or_else(|e| e.into_inner());
    let opts = HomogenizeOptions::default();
    let k = key(width, height, tensors, &opts)?;
    if let Some(t) = lock().get(k) {
        return Ok(t);
    }
    let t = homogenize_with(width, height, tensors, &opts)?;
    lock().insert(k, t);
    Ok(t)
}

//! What an [`AngleMesh`](super::AngleMesh) keeps between reconstructions: the solver state of the spectral
//! reconstruction and of the tracked one, which depend on the connectivity only (the
//! algorithms that build and use them are in `spectral.rs` and `track.rs`).

use std::sync::{Arc, Mutex};

use crate::ops::{CscPattern, LowerCsc, PrefactoredSpd};

/// Solver state an [`AngleMesh`](super::AngleMesh) keeps between reconstructions (it depends on the
/// connectivity only): taken out while a reconstruction runs and put back after, so
/// concurrent reconstructions of one mesh never share it (a second one builds its own);
/// a clone of the mesh starts empty. No result depends on it.
pub(crate) struct Kept<T>(Mutex<Option<T>>);

impl<T> Kept<T> {
    /// The kept state, or a new one from `build`.
    pub(crate) fn take_or<E>(&self, build: impl FnOnce() -> Result<T, E>) -> Result<T, E> {
        match self.0.lock().map(|mut g| g.take()).unwrap_or(None) {
            Some(t) => Ok(t),
            None => build(),
        }
    }
    /// Keeps `t` for the next reconstruction.
    pub(crate) fn put(&self, t: T) {
        if let Ok(mut g) = self.0.lock() {
            *g = Some(t);
        }
    }
}

impl<T> Default for Kept<T> {
    fn default() -> Self {
        Self(Mutex::new(None))
    }
}

impl<T> Clone for Kept<T> {
    /// A clone starts empty (the state is rebuilt on its first use).
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl<T> std::fmt::Debug for Kept<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let filled = self.0.lock().map(|g| g.is_some()).unwrap_or(false);
        f.debug_struct("Kept").field("filled", &filled).finish()
    }
}

/// `A₁`'s lower triangle in CSC: unknown `v` for vertex `v`, `V + f` for face `f`'s frame
/// column `m_f` (one coordinate). The arrays are shared, so a copy is cheap.
#[derive(Clone)]
pub(crate) struct Pattern {
    pub(super) n: usize,
    pub(super) col_ptr: Arc<[u32]>,
    pub(super) row_idx: Arc<[u32]>,
}

impl LowerCsc for Pattern {
    fn n(&self) -> usize {
        self.n
    }
    fn col_ptr(&self) -> &[u32] {
        &self.col_ptr
    }
    fn row_idx(&self) -> &[u32] {
        &self.row_idx
    }
}

/// What a reconstruction of one mesh can keep for the next (module docs, "Warm start"): the
/// pattern of `A₁` with its symbolic Cholesky analysis and factor buffers, which depend on
/// the connectivity only. Taken out while a reconstruction runs and put back after, so
/// concurrent reconstructions of one mesh never share it (a second one builds its own).
/// The cache changes no result: the numeric factorization is redone for every matrix.
pub(crate) type SolverCache = Kept<PrefactoredSpd<Pattern>>;

/// The two factorized Laplacians: the dual graph (faces, one pair per interior edge) and the
/// vertex graph (one pair per face side, so an interior edge counts twice); and a
/// breadth-first spanning tree of the dual graph from face 0, for the cold start.
pub(crate) struct Tracker {
    pub(super) dual: PrefactoredSpd<CscPattern>,
    pub(super) primal: PrefactoredSpd<CscPattern>,
    /// Every face but face 0 in breadth-first order, with the interior edge to its parent
    /// (the face across it, reached earlier).
    pub(super) tree: Vec<(u32, u32)>,
}

/// The mesh's [`Tracker`], built on first use and kept between frames.
pub(crate) type TrackerCache = Kept<Tracker>;

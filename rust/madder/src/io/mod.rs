//! Files: the Madder bake cache.

pub mod cache;

//! The MDD reader on arbitrary bytes: open (explicitly as MDD, and by sniffing a `.mdd`
//! name), then everything `common::exercise` does. Must never panic, abort or allocate
//! beyond the input.
#![no_main]

use libfuzzer_sys::fuzz_target;
use madder::io::point_cache::{Format, PointCache};

mod common;

fuzz_target!(|data: &[u8]| {
    common::with_file(data, "mdd", |path| {
        if let Ok(c) = PointCache::open_as(path, Format::Mdd) {
            common::exercise(c, data);
        }
        if let Err(e) = PointCache::open(path) {
            let _ = e.to_string();
        }
    });
});

//! One flat array filled by many tasks: the array cut into consecutive stretches, each a
//! mutable slice of its own, so that each task writes its stretch in place (the fans'
//! wedges, the transport's polar angles, the advection's turn table) instead of
//! building a vector of its own to be copied into the array afterwards.
//!
//! The same cut lets tasks write an array at increasing indices (the simulator's window
//! committed into the cloth's arrays, [`for_each_at`]): each run of indices owns the
//! stretch from its first index to the next run's first.

use rayon::prelude::*;

/// Indices per task of [`for_each_at`].
const PER_TASK: usize = 4096;

/// `slice` cut into consecutive stretches of the lengths `lens`, in order (what is left
/// after the last is not returned).
///
/// # Panics
/// If the lengths add up to more than the slice holds.
pub(crate) fn carve<T>(
    mut slice: &mut [T],
    lens: impl IntoIterator<Item = usize>,
) -> Vec<&mut [T]> {
    let lens = lens.into_iter();
    let mut out = Vec::with_capacity(lens.size_hint().0);
    for len in lens {
        let (head, tail) = std::mem::take(&mut slice).split_at_mut(len);
        out.push(head);
        slice = tail;
    }
    out
}

/// `write(k, &mut to[index[k]])` for every `k`, in parallel (each slot written by one
/// task, so the result does not depend on the thread count): `index` strictly
/// increasing, each run of [`PER_TASK`] indices writing inside the stretch of `to` from
/// its first index to the next run's first ([`carve`]).
///
/// # Panics
/// If `index` runs past `to` or is not increasing from one run to the next (strict
/// increase is checked in debug builds).
pub(crate) fn for_each_at<T: Send>(
    to: &mut [T],
    index: &[u32],
    write: impl Fn(usize, &mut T) + Sync,
) {
    debug_assert!(index.windows(2).all(|w| w[0] < w[1]), "increasing indices");
    let Some(&first) = index.first() else {
        return;
    };
    let starts: Vec<usize> = index
        .iter()
        .step_by(PER_TASK)
        .map(|&i| i as usize)
        .collect();
    let lens = starts
        .windows(2)
        .map(|w| w[1].checked_sub(w[0]).expect("increasing indices"))
        .chain([to
            .len()
            .checked_sub(*starts.last().unwrap())
            .expect("indices in range")]);
    carve(&mut to[first as usize..], lens)
        .into_par_iter()
        .zip(index.par_chunks(PER_TASK))
        .enumerate()
        .for_each(|(run, (stretch, indices))| {
            let base = starts[run];
            for (k, &i) in indices.iter().enumerate() {
                let slot = (i as usize)
                    .checked_sub(base)
                    .and_then(|s| stretch.get_mut(s))
                    .expect("increasing indices");
                write(run * PER_TASK + k, slot);
            }
        });
}

/// `to[index[k]] = from[k]` for every `k` ([`for_each_at`]: `index` strictly increasing).
///
/// # Panics
/// As [`for_each_at`], and if `from` and `index` differ in length.
pub(crate) fn scatter_at<T: Copy + Send + Sync>(to: &mut [T], index: &[u32], from: &[T]) {
    assert_eq!(index.len(), from.len(), "one value per index");
    for_each_at(to, index, |k, slot| *slot = from[k]);
}

/// `to = [from[i] for i in index]`, in parallel (its allocation kept).
pub(crate) fn gather_into<T: Copy + Send + Sync>(from: &[T], index: &[u32], to: &mut Vec<T>) {
    index
        .par_iter()
        .with_min_len(PER_TASK)
        .map(|&i| from[i as usize])
        .collect_into_vec(to);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stretches_are_consecutive_and_writable() {
        let mut a = [0u32; 10];
        for (k, s) in carve(&mut a, [3, 0, 4, 2]).into_iter().enumerate() {
            s.fill(k as u32 + 1);
        }
        assert_eq!(a, [1, 1, 1, 3, 3, 3, 3, 4, 4, 0]);
    }

    #[test]
    fn writes_at_increasing_indices_land_where_a_loop_puts_them() {
        // runs of several tasks, gaps of every size, the first and last slots
        let n = 3 * PER_TASK + 17;
        let index: Vec<u32> = (0..n as u32 * 3)
            .filter(|i| i % 3 != 1 || i % 7 == 0)
            .collect();
        let from: Vec<u64> = (0..index.len() as u64).map(|k| k * k + 1).collect();
        let mut want = vec![0u64; n * 3];
        for (&i, &x) in index.iter().zip(&from) {
            want[i as usize] = x;
        }
        let mut got = vec![0u64; n * 3];
        scatter_at(&mut got, &index, &from);
        assert_eq!(got, want);
        let mut picked = Vec::new();
        gather_into(&got, &index, &mut picked);
        assert_eq!(picked, from);
        // nothing to write
        scatter_at(&mut got, &[], &[]);
        assert_eq!(got, want);
    }

    #[test]
    #[should_panic(expected = "increasing indices")]
    fn indices_out_of_order_are_refused() {
        let mut to = vec![0u8; 2 * PER_TASK + 2];
        let mut index: Vec<u32> = (0..PER_TASK as u32 + 2).collect();
        index.swap(PER_TASK - 1, PER_TASK + 1);
        let from = vec![1u8; index.len()];
        scatter_at(&mut to, &index, &from);
    }
}

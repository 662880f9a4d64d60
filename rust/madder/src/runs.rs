//! One flat array filled by many tasks: the array cut into consecutive stretches, each a
//! mutable slice of its own, so that each task writes its stretch in place (the fans'
//! wedges, the transport's polar angles, the advection's turn table) instead of
//! building a vector of its own to be copied into the array afterwards.

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

#[cfg(test)]
mod tests {
    use super::carve;

    #[test]
    fn stretches_are_consecutive_and_writable() {
        let mut a = [0u32; 10];
        for (k, s) in carve(&mut a, [3, 0, 4, 2]).into_iter().enumerate() {
            s.fill(k as u32 + 1);
        }
        assert_eq!(a, [1, 1, 1, 3, 3, 3, 3, 4, 4, 0]);
    }
}

//! At most `limit` of `count` rows, evenly spaced: rows ⌊i · count / limit⌋ for i < limit.

/// The indices of at most `limit` of `count` rows, evenly spaced through them (all of them when
/// `count ≤ limit`).
pub fn evenly_spaced_rows(count: usize, limit: usize) -> Vec<usize> {
    if count > limit {
        (0..limit).map(|i| i * count / limit).collect()
    } else {
        (0..count).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_are_spread_from_the_first_and_all_kept_under_the_limit() {
        assert_eq!(evenly_spaced_rows(10, 4), vec![0, 2, 5, 7]);
        assert_eq!(evenly_spaced_rows(3, 4), vec![0, 1, 2]);
        assert_eq!(evenly_spaced_rows(5, 0), Vec::<usize>::new());
    }
}

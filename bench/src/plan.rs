//! The interleaved schedule every side-by-side benchmark follows.
//!
//! Running series A for a minute and then series B for a minute lets anything that changes in
//! between (a neighbour's compile on the host, thermal state, the page cache) land on one series
//! only. Instead each run is cut into rounds, and every round runs one short block of every
//! series. The order rotates from round to round, so no series always follows the same one or
//! always runs first after a pause.

/// `rounds` rounds over `items`; round `r` is `items` rotated left by `r`.
pub fn interleave<T: Copy>(items: &[T], rounds: usize) -> Vec<Vec<T>> {
    (0..rounds)
        .map(|r| {
            let mut order = items.to_vec();
            if !order.is_empty() {
                let k = r % order.len();
                order.rotate_left(k);
            }
            order
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_item_runs_once_per_round_and_in_every_position() {
        let items = [0usize, 1, 2, 3, 4];
        let plan = interleave(&items, 10);
        assert_eq!(plan.len(), 10);
        let mut at = [[0usize; 5]; 5]; // at[item][position]
        for round in &plan {
            let mut sorted = round.clone();
            sorted.sort();
            assert_eq!(sorted, items, "each item exactly once per round");
            for (pos, &item) in round.iter().enumerate() {
                at[item][pos] += 1;
            }
        }
        // 10 rounds over 5 items: every item holds every position exactly twice.
        assert!(at.iter().flatten().all(|&n| n == 2), "{at:?}");
        // Consecutive rounds differ, so no series is stuck behind the same neighbour.
        assert!(plan.windows(2).all(|w| w[0] != w[1]));
    }

    #[test]
    fn degenerate_inputs() {
        assert!(interleave::<u8>(&[], 3).iter().all(|r| r.is_empty()));
        assert!(interleave(&[1], 0).is_empty());
        assert_eq!(interleave(&[7], 2), vec![vec![7], vec![7]]);
    }
}

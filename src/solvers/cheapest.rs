//! A priority-queue entry for Dijkstra-like searches over `std::collections::BinaryHeap` (a
//! max-heap): the lowest cost pops first, ties broken by the smallest `tie`, so that a search
//! visits in one order whatever the heap's internals.

use std::cmp::Ordering;

/// A heap entry: `cost` (lowest first, by `f64::total_cmp`), then `tie` (smallest first).
#[derive(Clone, Copy, Debug)]
pub struct Cheapest<T> {
    pub cost: f64,
    pub tie: T,
}

impl<T: Ord> Ord for Cheapest<T> {
    fn cmp(&self, other: &Self) -> Ordering {
        (other.cost.total_cmp(&self.cost)).then_with(|| other.tie.cmp(&self.tie))
    }
}

impl<T: Ord> PartialOrd for Cheapest<T> {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl<T: Ord> PartialEq for Cheapest<T> {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}

impl<T: Ord> Eq for Cheapest<T> {}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BinaryHeap;

    #[test]
    fn the_lowest_cost_pops_first_and_ties_go_to_the_smallest() {
        let mut heap = BinaryHeap::new();
        for (cost, tie) in [(2.0, 0), (1.0, 5), (1.0, 3), (-0.5, 9), (2.0, 1)] {
            heap.push(Cheapest { cost, tie });
        }
        let order: Vec<(f64, u32)> = std::iter::from_fn(|| heap.pop())
            .map(|c| (c.cost, c.tie))
            .collect();
        assert_eq!(order, [(-0.5, 9), (1.0, 3), (1.0, 5), (2.0, 0), (2.0, 1)]);
    }
}

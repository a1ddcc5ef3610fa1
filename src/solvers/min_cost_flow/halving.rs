//! Halving (ours, beyond the paper): the flow solver's repair split between the two cores.
//!
//! The bins are cut into two ranges of indices where the start's conflicts (load outside the
//! bounds) are halved; the correction numbers its bins in cell order, last axis slowest, so a
//! cut is a plane of cells across that axis (in dam-3d, across the column's width). Each range
//! is solved on its own with the items that start in it, restricted to their candidates in the
//! range or in a bin that cannot bind (shared by both), the two side by side (and each halved
//! again, `levels` deep). The whole problem is then repaired from the halves' choices and
//! prices by the solver's own successive shortest paths: an item that has a cheaper candidate
//! across the cut under those prices first takes it, so every move starts at a non-negative
//! reduced cost, and the result is exact whatever the halves found. The halves only make the
//! start good; what is left to repair is what crosses the cut.
//!
//! The split is fixed by the problem alone (not by the number of threads), so the result is
//! the same on any machine. A half that is infeasible on its own (a bin with a lower bound
//! that only items of the other half can fill) sends the problem to the whole solver.

use super::{priced_choice, repair_from, BoundedAssignment, Infeasible, Solution};
use super::{PricedCosts, ITEM_BLOCK, NONE, PRICE_TIE};
use rayon::prelude::*;
use std::ops::Range;

/// How deep [`solve_halved`] halves, and below what size it stops.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Halving {
    /// Levels of halving: 1 solves two halves, 2 four quarters (two at a time on two cores).
    pub levels: u32,
    /// Problems with fewer items are solved whole: their repair is shorter than the copies.
    pub min_items: usize,
}

/// The correction's halving: one level, on problems of at least 100,000 items. Measured on
/// dam-3d without the band (`cellflip bench --scene dam-3d --method ccp --band none`, flow
/// solver medians, alternating runs): at 140^3 (1.19 M items) 3.1 s whole, 2.1 s halved; at
/// 100^3 (432,000) 406-419 ms against 354-364 ms; at 64^3 (111,188) 105-107 against 100-102 ms;
/// at 50^3 (54,000) 22-23 against 26-27 ms, where the copies cost more than the halves save.
/// A threshold of 40,000, measured once halves reused the whole start (`bench --steps 10..20`,
/// two alternating runs): dam-3d 50^3 no band 22.9/23.2 -> 24.4/23.0 ms, its band problems
/// 15.7/15.2 -> 13.0/12.0 ms, but dam-2d at 300^2 (64,800) 134/129 -> 174/181 ms, where the
/// last axis is the vertical and the cut crosses the climbing excess; so 100,000 stays (at
/// 500^2, 180,000 particles, halved 684/666 ms against 706/715 ms for the binary before halving).
/// Two levels (four quarters, two at a time) took 3.8 s on the exported 100^3 step 8 (`cellflip
/// solve`), against 0.54 s with one level and 0.80 s whole: slabs 8 cells thick across the
/// column leave most of its excess to the repairs after them (32,718 augmentations against
/// 12,778 with one level and 12,487 whole).
pub const HALVING: Halving = Halving {
    levels: 1,
    min_items: 100_000,
};

/// Solves `p` exactly from `prices` (as [`super::solve_warm`]), its repair split by `halving`.
pub fn solve_halved(
    p: &BoundedAssignment,
    prices: &[f64],
    halving: Halving,
) -> Result<Solution, Infeasible> {
    halve_from(p, priced_choice(p, prices), prices, halving)
}

/// Solves `p` from `start`, every item's cheapest candidate under `prices` ([`priced_choice`]),
/// its repair split by `halving`.
fn halve_from(
    p: &BoundedAssignment,
    start: Vec<u32>,
    prices: &[f64],
    halving: Halving,
) -> Result<Solution, Infeasible> {
    if halving.levels == 0 || p.items() < halving.min_items {
        return repair_from(p, start, prices);
    }
    let conflicts = Conflicts::of(p, &start);
    let Some(cut) = conflicts.halved_at() else {
        return repair_from(p, start, prices);
    };
    let inner = Halving {
        levels: halving.levels - 1,
        ..halving
    };
    let ranges = [0..cut, cut..p.bins()];
    let free = p.binding_bins().iter().map(|&b| !b).collect::<Vec<_>>();
    let whole = Whole {
        p,
        start: &start,
        prices,
        free: &free,
    };
    let (low, high) = rayon::join(
        || Half::solve(whole, ranges[0].clone(), inner),
        || Half::solve(whole, ranges[1].clone(), inner),
    );
    let (Ok(low), Ok(high)) = (low, high) else {
        return repair_from(p, start, prices);
    };
    let mut choice = start;
    let mut merged = vec![0.0; p.bins()];
    for half in [&low, &high] {
        half.write(&mut choice, &mut merged);
    }
    take_cheaper_candidates(p, &mut choice, &merged);
    let mut solution = repair_from(p, choice, &merged)?;
    solution.stats.overfull_bins = conflicts.overfull_bins;
    solution.stats.underfull_bins = conflicts.underfull_bins;
    solution.stats.halvings += 1;
    for half in [&low, &high] {
        solution.stats.augmentations += half.solution.stats.augmentations;
        solution.stats.nodes_settled += half.solution.stats.nodes_settled;
        solution.stats.halvings += half.solution.stats.halvings;
    }
    Ok(solution)
}

/// The start's conflicts: per bin, the units over its upper bound or under its lower bound.
struct Conflicts {
    units: Vec<u32>,
    overfull_bins: usize,
    underfull_bins: usize,
}

impl Conflicts {
    fn of(p: &BoundedAssignment, start: &[u32]) -> Self {
        let mut load = vec![0u32; p.bins()];
        for &k in start {
            load[p.cand_bin[k as usize] as usize] += 1;
        }
        let over = |b: usize| load[b].saturating_sub(p.upper[b]);
        let under = |b: usize| p.lower[b].saturating_sub(load[b]);
        Self {
            units: (0..p.bins()).map(|b| over(b) + under(b)).collect(),
            overfull_bins: (0..p.bins()).filter(|&b| over(b) > 0).count(),
            underfull_bins: (0..p.bins()).filter(|&b| under(b) > 0).count(),
        }
    }

    /// The bin index that halves the conflicts (the bins before it hold at least half the
    /// units), or `None` if there are none or all are in the last bin.
    fn halved_at(&self) -> Option<usize> {
        let total: u64 = self.units.iter().map(|&u| u as u64).sum();
        let mut seen = 0;
        let half = self.units.iter().position(|&u| {
            seen += u as u64;
            2 * seen >= total
        });
        half.map(|b| b + 1)
            .filter(|&cut| total > 0 && cut < self.units.len())
    }
}

/// What both halves read of the whole problem.
#[derive(Clone, Copy)]
struct Whole<'a> {
    p: &'a BoundedAssignment,
    start: &'a [u32],
    prices: &'a [f64],
    /// The bins that cannot bind ([`BoundedAssignment::binding_bins`]), which both halves share.
    free: &'a [bool],
}

/// One range of bins solved on its own.
struct Half {
    /// The range's bins.
    bins: Range<usize>,
    /// The items that start in the range, in order, and each kept candidate's index in the
    /// whole problem.
    items: Vec<u32>,
    original: Vec<u32>,
    solution: Solution,
}

impl Half {
    /// Solves the items that start in bins `bins`, with their candidates in `bins` or in a bin
    /// that cannot bind. Such a bin has room for all its candidates, so the two halves can
    /// share it without overfilling it, and a half keeps the room next to it across the cut.
    /// (An exported problem read back numbers these bins after all the others, so without
    /// them one half would lose its room.) The half's bins are the range's, then the shared
    /// ones outside it as they are met.
    fn solve(whole: Whole<'_>, bins: Range<usize>, halving: Halving) -> Result<Self, Infeasible> {
        let Whole { p, start, .. } = whole;
        let mut bin_of = vec![NONE; p.bins()];
        bins.clone()
            .for_each(|b| bin_of[b] = (b - bins.start) as u32);
        // The half's items and kept candidates, counted first so that its lists are allocated
        // once at their size: room for the whole problem's would be resident wherever the
        // allocator hands out memory a step before touched.
        let kept = |b: usize| bins.contains(&b) || whole.free[b];
        let in_half = |k0: u32| bins.contains(&(p.cand_bin[k0 as usize] as usize));
        let (mut n_items, mut n_cands) = (0, 0);
        for i in (0..start.len()).filter(|&i| in_half(start[i])) {
            n_items += 1;
            n_cands += p
                .candidates(i)
                .filter(|&k| kept(p.cand_bin[k] as usize))
                .count();
        }
        let mut q = BoundedAssignment {
            item_start: Vec::with_capacity(n_items + 1),
            cand_bin: Vec::with_capacity(n_cands),
            cand_cost: Vec::with_capacity(n_cands),
            lower: p.lower[bins.clone()].to_vec(),
            upper: p.upper[bins.clone()].to_vec(),
        };
        q.item_start.push(0);
        let mut q_prices = whole.prices[bins.clone()].to_vec();
        let mut original = Vec::with_capacity(n_cands);
        let (mut items, mut q_start) = (Vec::with_capacity(n_items), Vec::with_capacity(n_items));
        for (i, &k0) in start.iter().enumerate() {
            if !in_half(k0) {
                continue;
            }
            items.push(i as u32);
            for k in p.candidates(i) {
                if k == k0 as usize {
                    q_start.push(q.cand_bin.len() as u32);
                }
                let b = p.cand_bin[k] as usize;
                if !kept(b) {
                    continue;
                }
                if bin_of[b] == NONE {
                    bin_of[b] = q.lower.len() as u32;
                    q.lower.push(p.lower[b]);
                    q.upper.push(p.upper[b]);
                    q_prices.push(whole.prices[b]);
                }
                q.cand_bin.push(bin_of[b]);
                q.cand_cost.push(p.cand_cost[k]);
                original.push(k as u32);
            }
            q.item_start.push(q.cand_bin.len());
        }
        // The item's cheapest candidate under the prices is still its cheapest of those kept,
        // and the first of equals: the half's start is the whole one's.
        let solution = halve_from(&q, q_start, &q_prices, halving)?;
        Ok(Self {
            bins,
            items,
            original,
            solution,
        })
    }

    /// Writes the half's choices into `choice` and the prices of its range, relative to its
    /// sink's, into `prices`.
    fn write(&self, choice: &mut [u32], prices: &mut [f64]) {
        let s = &self.solution;
        for (&i, &k) in self.items.iter().zip(&s.choice) {
            choice[i as usize] = self.original[k as usize];
        }
        for (out, &price) in prices[self.bins.clone()].iter_mut().zip(&s.prices) {
            *out = price - s.sink_price;
        }
    }
}

/// Moves every item with a candidate cheaper by more than [`PRICE_TIE`] under `prices` (cost
/// plus its bin's price) to its cheapest one, so that every move of an item has a non-negative
/// reduced cost: what the repair needs of its start. Within a half its prices already certify
/// its choice; only items near the cut move.
fn take_cheaper_candidates(p: &BoundedAssignment, choice: &mut [u32], prices: &[f64]) {
    let priced = PricedCosts { p, prices };
    (choice.par_iter_mut().enumerate())
        .with_min_len(ITEM_BLOCK)
        .for_each(|(i, k)| {
            let best = priced.cheapest(i);
            if priced.of(best) < priced.of(*k as usize) - PRICE_TIE {
                *k = best as u32;
            }
        });
}

#[cfg(test)]
mod tests {
    use super::super::tests::problem;
    use super::*;

    fn conflicts(units: &[u32]) -> Conflicts {
        Conflicts {
            units: units.to_vec(),
            overfull_bins: 0,
            underfull_bins: 0,
        }
    }

    #[test]
    fn the_cut_halves_the_conflicts() {
        assert_eq!(conflicts(&[0, 2, 0, 1, 1]).halved_at(), Some(2));
        assert_eq!(conflicts(&[1, 0, 0, 0, 1]).halved_at(), Some(1));
        assert_eq!(conflicts(&[0, 0, 3, 0]).halved_at(), Some(3));
        assert_eq!(
            conflicts(&[0, 0, 0, 3]).halved_at(),
            None,
            "nothing before the cut"
        );
        assert_eq!(conflicts(&[0, 0, 0]).halved_at(), None, "no conflicts");
    }

    #[test]
    fn the_start_counts_units_over_and_under_the_bounds() {
        // Items 0-2 start in bin 0 (room for 1), item 3 in bin 1; bin 2 must hold 2.
        let p = problem(
            &[
                &[(0, 0.0), (2, 1.0)],
                &[(0, 0.0), (2, 1.0)],
                &[(0, 0.0), (1, 1.0)],
                &[(1, 0.0), (2, 1.0)],
            ],
            &[0, 0, 2],
            &[1, 3, 2],
        );
        let c = Conflicts::of(&p, &[0, 2, 4, 6]);
        assert_eq!(c.units, vec![2, 0, 2]);
        assert_eq!((c.overfull_bins, c.underfull_bins), (1, 1));
        assert_eq!(c.halved_at(), Some(1));
    }

    #[test]
    fn both_halves_share_a_bin_that_cannot_bind() {
        // Bins 0 and 2 (room for 1) each start with two items, so the cut falls after bin 0;
        // bin 3 has room for every candidate into it, and is the only way out of both.
        let p = problem(
            &[
                &[(0, 0.0), (3, 1.0)],
                &[(0, 0.0), (3, 2.0)],
                &[(2, 0.0), (3, 1.0)],
                &[(2, 0.0), (3, 1.5)],
            ],
            &[0; 4],
            &[1, 1, 1, 10],
        );
        let halving = Halving {
            levels: 1,
            min_items: 0,
        };
        let s = solve_halved(&p, &[0.0; 4], halving).unwrap();
        assert_eq!(
            s.stats.halvings, 1,
            "the half before the cut is feasible with bin 3"
        );
        p.check(&s.choice).unwrap();
        assert_eq!(p.objective(&s.choice), 2.0);
        assert_eq!(s.choice, vec![1, 2, 5, 6]);
    }
}

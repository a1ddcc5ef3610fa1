//! An exact min-cost-flow solver for bounded assignment problems: every item picks exactly one
//! of its candidate bins, each candidate has a cost, and each bin's load must stay within
//! `[lower, upper]`. This is the network form of the paper's eq. problem3 (its matrix is totally
//! unimodular, prop. LPrelax), solved without any simplex.
//!
//! The network: items -> bins (unit arcs with the candidate costs) -> a sink `t` (one arc per
//! bin with flow bounds `[lower, upper]`). The solver starts from the cheapest candidate of
//! every item, which is optimal when bounds are ignored, and then repairs only the bins in
//! conflict by successive shortest paths (Ahuja, Magnanti, Orlin, *Network Flows*, sec. 9.7):
//!
//! 1. every over-full bin sends its excess, one unit at a time, along a shortest path in the
//!    residual network to the nearest bin below its lower bound or to `t` (through any bin
//!    with room);
//! 2. every bin still below its lower bound then receives units from `t` (through any bin
//!    above its lower bound) along shortest paths found by a reverse search.
//!
//! A path moves a chain of items, each to another of its candidates. Node potentials keep all
//! reduced costs non-negative, so Dijkstra's algorithm applies and the result is optimal; each
//! search starts at one bin in conflict and stops at the nearest target, so the work grows with
//! the conflicts, not with the number of items. Ties break by node index: results are
//! deterministic.

mod halving;

use super::cheapest::Cheapest;
use super::NONE;
pub use halving::{solve_halved, Halving, HALVING};
use rayon::prelude::*;
use std::collections::BinaryHeap;
use std::ops::Range;

/// Items choosing one candidate bin each, with per-bin load bounds.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BoundedAssignment {
    /// The candidates of item `i` are `item_start[i]..item_start[i + 1]`.
    pub item_start: Vec<usize>,
    /// Bin of each candidate.
    pub cand_bin: Vec<u32>,
    /// Cost of each candidate.
    pub cand_cost: Vec<f64>,
    /// Least load of each bin.
    pub lower: Vec<u32>,
    /// Largest load of each bin.
    pub upper: Vec<u32>,
}

impl BoundedAssignment {
    pub fn items(&self) -> usize {
        self.item_start.len().saturating_sub(1)
    }

    pub fn bins(&self) -> usize {
        self.lower.len()
    }

    pub fn candidates(&self, item: usize) -> Range<usize> {
        self.item_start[item]..self.item_start[item + 1]
    }

    /// The same problem with only the candidates for which `keep(item, candidate)` holds;
    /// also returns the original index of every kept candidate.
    pub fn restrict(&self, mut keep: impl FnMut(usize, usize) -> bool) -> (Self, Vec<u32>) {
        let mut out = Self {
            item_start: vec![0],
            lower: self.lower.clone(),
            upper: self.upper.clone(),
            ..Default::default()
        };
        let mut original = vec![];
        for i in 0..self.items() {
            for k in self.candidates(i).filter(|&k| keep(i, k)) {
                out.cand_bin.push(self.cand_bin[k]);
                out.cand_cost.push(self.cand_cost[k]);
                original.push(k as u32);
            }
            out.item_start.push(out.cand_bin.len());
        }
        (out, original)
    }

    /// Bins whose bounds can bind: a lower bound, or more candidates than room.
    pub fn binding_bins(&self) -> Vec<bool> {
        let arcs = candidates_per_bin(self);
        (0..self.bins())
            .map(|b| self.lower[b] > 0 || arcs[b] > self.upper[b] as usize)
            .collect()
    }

    /// Total cost of a choice (one global candidate index per item).
    pub fn objective(&self, choice: &[u32]) -> f64 {
        choice.iter().map(|&k| self.cand_cost[k as usize]).sum()
    }

    /// Checks that `choice` picks one of each item's own candidates and keeps every bin within
    /// its bounds.
    pub fn check(&self, choice: &[u32]) -> Result<(), InvalidChoice> {
        if choice.len() != self.items() {
            return Err(InvalidChoice::Count {
                choices: choice.len(),
                items: self.items(),
            });
        }
        let mut load = vec![0u32; self.bins()];
        for (item, &k) in choice.iter().enumerate() {
            if !self.candidates(item).contains(&(k as usize)) {
                return Err(InvalidChoice::NotOwn { item, candidate: k });
            }
            load[self.cand_bin[k as usize] as usize] += 1;
        }
        for (bin, &load) in load.iter().enumerate() {
            let (lower, upper) = (self.lower[bin], self.upper[bin]);
            if load < lower || load > upper {
                return Err(InvalidChoice::OutOfBounds {
                    bin,
                    load,
                    lower,
                    upper,
                });
            }
        }
        Ok(())
    }
}

/// Why a choice is not an assignment of the problem ([`BoundedAssignment::check`]).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum InvalidChoice {
    #[error("{choices} choices for {items} items")]
    Count { choices: usize, items: usize },
    #[error("item {item} picked candidate {candidate}, not one of its own")]
    NotOwn { item: usize, candidate: u32 },
    #[error("bin {bin} holds {load}, outside [{lower}, {upper}]")]
    OutOfBounds {
        bin: usize,
        load: u32,
        lower: u32,
        upper: u32,
    },
}

/// What a solve did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FlowStats {
    /// Units sent along augmenting paths.
    pub augmentations: usize,
    /// Nodes settled by all the searches together.
    pub nodes_settled: usize,
    /// Bins over their upper bound at the start.
    pub overfull_bins: usize,
    /// Bins under their lower bound at the start.
    pub underfull_bins: usize,
    /// Problems split in two by [`solve_halved`] (the whole one and any halves halved again).
    pub halvings: usize,
}

/// The problem has no feasible assignment: a search from `bin` found no way to repair it.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("no feasible assignment: bin {bin} cannot be repaired")]
pub struct Infeasible {
    pub bin: usize,
}

/// Prices this close count as equal when a start's sink flows are set: the rounding of the
/// potential updates, far below any cost difference that matters (costs are squared distances
/// in cells).
const PRICE_TIE: f64 = 1e-9;

/// What a search reads of a node when it offers the node a distance, in one 32-byte block (one
/// cache line, where separate arrays took four): its potential, the bin's load and sink flow
/// (unused for the sink), and its label in the current search.
#[derive(Clone, Copy, Debug, Default)]
#[repr(align(32))]
struct Node {
    potential: f64,
    /// Distance in the current search, valid where `stamp` is the current search.
    dist: f64,
    stamp: u32,
    settled: bool,
    /// Items in the bin: `bin_items[b].len()`, kept here too so that a search reads it in
    /// the same cache line.
    load: u32,
    /// Flow on the arc bin -> t, kept within `[lower, upper]`.
    sink_flow: u32,
}

impl Node {
    /// Whether the bin holds fewer items than its sink flow: a search's target.
    fn short(&self) -> bool {
        self.load < self.sink_flow
    }
}

/// How the current search reached a node, read only when a path is walked.
#[derive(Clone, Copy, Debug, Default)]
struct Link {
    /// Forward search: the node this one was reached from. Reverse search: the node it leads to.
    node: u32,
    /// The candidate moved along that link (`NONE` for an arc to or from `t`).
    cand: u32,
}

/// The cheapest way to move one item between a bin and bin `other` (out of the bin in its
/// out-arcs, into it in its in-arcs): the item's candidate `cand` in the bin it moves to, at
/// `delta` = its cost there minus its cost now. Potentials are per bin, so this item also has
/// the least reduced cost among the items that could make the same move: a search needs only
/// this arc.
#[derive(Clone, Copy, Debug)]
struct BinArc {
    other: u32,
    cand: u32,
    delta: f64,
}

/// Per bin, its cheapest move to (or from) each other bin, rebuilt when `stale`. Allocated at
/// its first use: many solves run no reverse search, and never build their in-arcs.
struct ArcCache {
    bins: usize,
    arcs: Vec<Vec<BinArc>>,
    stale: Vec<bool>,
}

impl ArcCache {
    fn new(bins: usize) -> Self {
        Self {
            bins,
            arcs: vec![],
            stale: vec![],
        }
    }

    /// Whether any arcs were built: before that there is nothing to invalidate.
    fn built(&self) -> bool {
        !self.stale.is_empty()
    }

    /// Marks bin `b`'s arcs for a rebuild at their next use.
    #[inline]
    fn invalidate(&mut self, b: u32) {
        if let Some(s) = self.stale.get_mut(b as usize) {
            *s = true;
        }
    }

    /// Rebuilds bin `v`'s arcs if they are stale: `fill` offers every move, and the least
    /// `delta` per other bin is kept (the first of equals). `arc_of` is scratch, all `NONE`
    /// outside a rebuild.
    #[inline]
    fn refresh(&mut self, v: usize, arc_of: &mut [u32], fill: impl FnOnce(&mut ArcList<'_>)) {
        if !self.built() {
            self.arcs = vec![vec![]; self.bins];
            self.stale = vec![true; self.bins];
        }
        if !std::mem::take(&mut self.stale[v]) {
            return;
        }
        let arcs = &mut self.arcs[v];
        arcs.clear();
        fill(&mut ArcList { arcs, arc_of });
        for a in arcs.iter() {
            arc_of[a.other as usize] = NONE;
        }
    }
}

/// A bin's arcs being rebuilt, with `arc_of`: per other bin, its arc's index in the list, so
/// that a rebuild takes linear time in the moves offered.
struct ArcList<'a> {
    arcs: &'a mut Vec<BinArc>,
    arc_of: &'a mut [u32],
}

impl ArcList<'_> {
    /// Keeps `arc` if it is the first or the cheapest move so far to or from its other bin.
    #[inline]
    fn offer(&mut self, arc: BinArc) {
        let o = arc.other as usize;
        match self.arc_of[o] {
            NONE => {
                self.arc_of[o] = self.arcs.len() as u32;
                self.arcs.push(arc);
            }
            at if arc.delta < self.arcs[at as usize].delta => self.arcs[at as usize] = arc,
            _ => {}
        }
    }
}

/// Solver state: the current assignment, the sink flows and the node potentials.
struct Network<'a> {
    p: &'a BoundedAssignment,
    /// Item of each candidate.
    cand_item: Vec<u32>,
    /// Candidates into each bin: `bin_cands[bin_start[b]..bin_start[b + 1]]`.
    bin_start: Vec<usize>,
    bin_cands: Vec<u32>,
    choice: Vec<u32>,
    /// Per node (the bins, then the sink `t`): potential, load, sink flow, search label.
    node: Vec<Node>,
    link: Vec<Link>,
    /// Items currently in each bin, and each item's place in its bin's list.
    bin_items: Vec<Vec<u32>>,
    slot: Vec<u32>,
    /// Per bin, the cheapest move of its items to each other bin (read by forward searches),
    /// and the cheapest move into it from each other bin (read by reverse searches).
    out_arcs: ArcCache,
    in_arcs: ArcCache,
    /// Scratch of [`ArcCache::refresh`].
    arc_of: Vec<u32>,
    /// The current search's stamp (see [`Node::stamp`]).
    search: u32,
    /// Nodes by smallest distance, then smallest node.
    heap: BinaryHeap<Cheapest<u32>>,
    visited: Vec<u32>,
    /// Smallest tentative distance of a target in the current search: nothing farther can lead
    /// to a nearer target (costs are non-negative), so nothing farther is queued.
    bound: f64,
    stats: FlowStats,
}

/// Items per block when a loop over items is split between threads.
const ITEM_BLOCK: usize = 4096;

/// The item of every candidate, filled in parallel over blocks of items.
fn item_of_candidates(p: &BoundedAssignment) -> Vec<u32> {
    let mut cand_item = vec![0u32; p.cand_bin.len()];
    let mut blocks = vec![];
    let mut rest = cand_item.as_mut_slice();
    for first in (0..p.items()).step_by(ITEM_BLOCK) {
        let items = first..(first + ITEM_BLOCK).min(p.items());
        let len = p.item_start[items.end] - p.item_start[first];
        let (block, tail) = std::mem::take(&mut rest).split_at_mut(len);
        blocks.push((items, block));
        rest = tail;
    }
    blocks.into_par_iter().for_each(|(items, block)| {
        let base = p.item_start[items.start];
        for i in items {
            let ks = p.candidates(i);
            block[ks.start - base..ks.end - base].fill(i as u32);
        }
    });
    cand_item
}

/// The number of candidates into each bin, counted in parallel over chunks of candidates.
fn candidates_per_bin(p: &BoundedAssignment) -> Vec<usize> {
    let bins = p.bins();
    (p.cand_bin.par_chunks(1 << 16))
        .fold(
            || vec![0usize; bins],
            |mut n, chunk| {
                chunk.iter().for_each(|&b| n[b as usize] += 1);
                n
            },
        )
        .reduce_with(|mut a, b| {
            a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
            a
        })
        .unwrap_or_else(|| vec![0; bins])
}

/// The candidates into each bin, in increasing order: `cands[start[b]..start[b + 1]]`. A
/// counting sort, split between threads by ranges of bins: each reads every candidate and
/// writes those of its own bins, so every output slice has one writer.
fn candidates_by_bin(p: &BoundedAssignment) -> (Vec<usize>, Vec<u32>) {
    let bins = p.bins();
    let counts = candidates_per_bin(p);
    let mut start = Vec::with_capacity(bins + 1);
    start.push(0);
    for n in counts {
        start.push(start.last().unwrap() + n);
    }
    let mut cands = vec![0u32; p.cand_bin.len()];
    let pieces = rayon::current_num_threads().clamp(1, bins.max(1));
    let mut slices = vec![];
    let mut rest = cands.as_mut_slice();
    for j in 0..pieces {
        let range = bins * j / pieces..bins * (j + 1) / pieces;
        let len = start[range.end] - start[range.start];
        let (slice, tail) = std::mem::take(&mut rest).split_at_mut(len);
        slices.push((range, slice));
        rest = tail;
    }
    slices.into_par_iter().for_each(|(range, slice)| {
        let base = start[range.start];
        let mut fill: Vec<usize> = start[range.clone()].iter().map(|s| s - base).collect();
        for (k, &b) in p.cand_bin.iter().enumerate() {
            if let Some(at) = (b as usize)
                .checked_sub(range.start)
                .and_then(|r| fill.get_mut(r))
            {
                slice[*at] = k as u32;
                *at += 1;
            }
        }
    });
    (start, cands)
}

/// The cheapest candidate of every item (ties go to the first): optimal when bounds are ignored.
fn cheapest_choice(p: &BoundedAssignment) -> Vec<u32> {
    (0..p.items())
        .map(|i| first_cheapest(p.candidates(i), |k| p.cand_cost[k]) as u32)
        .collect()
}

/// The candidate of `ks` with the least `cost` (the first of equals), each priced once.
fn first_cheapest(ks: Range<usize>, cost: impl Fn(usize) -> f64) -> usize {
    assert!(!ks.is_empty(), "every item has a candidate");
    let mut best = (cost(ks.start), ks.start);
    for k in ks.start + 1..ks.end {
        let c = cost(k);
        if c.total_cmp(&best.0).is_lt() {
            best = (c, k);
        }
    }
    best.1
}

impl<'a> Network<'a> {
    /// The network at assignment `choice`, with zero potentials.
    fn new(p: &'a BoundedAssignment, choice: Vec<u32>) -> Self {
        let bins = p.bins();
        let cand_item = item_of_candidates(p);
        let (bin_start, bin_cands) = candidates_by_bin(p);
        let mut bin_items: Vec<Vec<u32>> = vec![vec![]; bins];
        let mut slot = vec![0u32; choice.len()];
        for (item, &k) in choice.iter().enumerate() {
            let b = p.cand_bin[k as usize] as usize;
            slot[item] = bin_items[b].len() as u32;
            bin_items[b].push(item as u32);
        }
        let mut node: Vec<Node> = (bin_items.iter().enumerate())
            .map(|(b, items)| {
                let load = items.len() as u32;
                Node {
                    load,
                    sink_flow: load.clamp(p.lower[b], p.upper[b]),
                    ..Node::default()
                }
            })
            .collect();
        node.push(Node::default());
        Self {
            p,
            cand_item,
            bin_start,
            bin_cands,
            choice,
            link: vec![Link::default(); node.len()],
            node,
            bin_items,
            slot,
            out_arcs: ArcCache::new(bins),
            in_arcs: ArcCache::new(bins),
            arc_of: vec![NONE; bins],
            search: 0,
            heap: BinaryHeap::new(),
            visited: vec![],
            bound: f64::INFINITY,
            stats: FlowStats::default(),
        }
    }

    /// Sets the potentials to `prices` (one per bin) and `sink_price`, and each bin's sink flow
    /// to what keeps the arcs to and from the sink at non-negative reduced cost: the upper
    /// bound for a bin priced above the sink, the lower bound for one below it, and its load
    /// within the bounds for one priced like the sink (within [`PRICE_TIE`]). The repair then
    /// moves the difference between load and sink flow.
    fn set_prices(&mut self, prices: &[f64], sink_price: f64) {
        let p = self.p;
        for (b, (n, &price)) in self.node.iter_mut().zip(prices).enumerate() {
            let above = price - sink_price;
            n.sink_flow = if above > PRICE_TIE {
                p.upper[b]
            } else if above < -PRICE_TIE {
                p.lower[b]
            } else {
                n.load.clamp(p.lower[b], p.upper[b])
            };
            n.potential = price;
        }
        self.node[p.bins()].potential = sink_price;
    }

    fn sink(&self) -> u32 {
        self.p.bins() as u32
    }

    fn begin_search(&mut self, start: u32) {
        self.search += 1;
        self.heap.clear();
        self.visited.clear();
        self.bound = f64::INFINITY;
        self.touch(start, 0.0, NONE, NONE, false);
    }

    /// Offers distance `d` to node `v` (reached over `node` by moving candidate `cand`);
    /// `target` says whether `v` ends the search.
    fn touch(&mut self, v: u32, d: f64, node: u32, cand: u32, target: bool) {
        if d > self.bound {
            return;
        }
        if target {
            self.bound = d;
        }
        let i = v as usize;
        let n = &mut self.node[i];
        if n.stamp != self.search {
            n.stamp = self.search;
            n.settled = false;
        } else if n.settled || n.dist <= d {
            return;
        }
        n.dist = d;
        self.link[i] = Link { node, cand };
        self.heap.push(Cheapest { cost: d, tie: v });
    }

    /// Pops the nearest unsettled node and settles it.
    fn pop(&mut self) -> Option<(f64, u32)> {
        while let Some(Cheapest { cost: d, tie: v }) = self.heap.pop() {
            let n = &mut self.node[v as usize];
            if n.settled || d > n.dist {
                continue;
            }
            n.settled = true;
            self.visited.push(v);
            self.stats.nodes_settled += 1;
            return Some((d, v));
        }
        None
    }

    /// The reduced cost of a move from bin `a` to bin `b` whose cost changes by `delta`.
    fn reduced_delta(&self, delta: f64, a: usize, b: usize) -> f64 {
        (delta - self.node[a].potential + self.node[b].potential).max(0.0)
    }

    /// Potentials after a forward search that reached its target at distance `reach`:
    /// `pi(v) -= min(d(v), reach)`, up to a common shift that reduced costs ignore.
    fn lift_after_forward(&mut self, reach: f64) {
        for &v in &self.visited {
            let n = &mut self.node[v as usize];
            n.potential += reach - n.dist;
        }
    }

    /// Potentials after a reverse search: `pi(v) += min(r(v), reach)`, up to a common shift.
    fn lift_after_reverse(&mut self, reach: f64) {
        for &v in &self.visited {
            let n = &mut self.node[v as usize];
            n.potential -= reach - n.dist;
        }
    }

    /// Sends one unit of the excess of over-full bin `s` to the nearest bin under its lower
    /// bound, or to the sink through a bin with room.
    fn push_excess(&mut self, s: u32) -> Result<(), Infeasible> {
        let t = self.sink();
        self.begin_search(s);
        let target = loop {
            let Some((d, v)) = self.pop() else {
                return Err(Infeasible { bin: s as usize });
            };
            let vi = v as usize;
            if v == t || self.node[vi].short() {
                break (d, v);
            }
            // The cheapest item of `v` moving to each other bin.
            self.refresh_out_arcs(vi);
            for j in 0..self.out_arcs.arcs[vi].len() {
                let BinArc { other, cand, delta } = self.out_arcs.arcs[vi][j];
                let rc = self.reduced_delta(delta, vi, other as usize);
                let target = self.node[other as usize].short();
                self.touch(other, d + rc, v, cand, target);
            }
            if self.node[vi].sink_flow < self.p.upper[vi] {
                let rc = (self.node[t as usize].potential - self.node[vi].potential).max(0.0);
                self.touch(t, d + rc, v, NONE, true);
            }
        };
        self.lift_after_forward(target.0);
        // Walk back from the target, moving one item per link.
        let mut x = target.1;
        if x == t {
            let c = self.link[t as usize].node;
            self.node[c as usize].sink_flow += 1;
            x = c;
        }
        while x != s {
            let Link { node: w, cand } = self.link[x as usize];
            self.move_item(cand as usize, w, x);
            x = w;
        }
        self.stats.augmentations += 1;
        Ok(())
    }

    /// Brings one unit from the sink to bin `s`, which is under its lower bound, along the
    /// shortest path into `s` (a reverse search).
    fn pull_deficit(&mut self, s: u32) -> Result<(), Infeasible> {
        let t = self.sink();
        self.begin_search(s);
        let reach = loop {
            let Some((r, v)) = self.pop() else {
                return Err(Infeasible { bin: s as usize });
            };
            if v == t {
                break r;
            }
            let vi = v as usize;
            // The cheapest item of each other bin moving into `v`.
            self.refresh_in_arcs(vi);
            for j in 0..self.in_arcs.arcs[vi].len() {
                let BinArc { other, cand, delta } = self.in_arcs.arcs[vi][j];
                let rc = self.reduced_delta(delta, other as usize, vi);
                self.touch(other, r + rc, v, cand, false);
            }
            if self.node[vi].sink_flow > self.p.lower[vi] {
                let rc = (self.node[vi].potential - self.node[t as usize].potential).max(0.0);
                self.touch(t, r + rc, v, NONE, true);
            }
        };
        self.lift_after_reverse(reach);
        // Walk forward from the sink: t -> c, then one item per link until `s`.
        let mut x = self.link[t as usize].node;
        self.node[x as usize].sink_flow -= 1;
        while x != s {
            let Link { node: next, cand } = self.link[x as usize];
            self.move_item(cand as usize, x, next);
            x = next;
        }
        self.stats.augmentations += 1;
        Ok(())
    }

    /// Rebuilds the cheapest move of bin `v`'s items to each other bin if they changed.
    fn refresh_out_arcs(&mut self, v: usize) {
        let (p, choice, items) = (self.p, &self.choice, &self.bin_items[v]);
        self.out_arcs.refresh(v, &mut self.arc_of, |list| {
            for &item in items {
                let k = choice[item as usize] as usize;
                for k2 in p.candidates(item as usize).filter(|&k2| k2 != k) {
                    list.offer(BinArc {
                        other: p.cand_bin[k2],
                        cand: k2 as u32,
                        delta: p.cand_cost[k2] - p.cand_cost[k],
                    });
                }
            }
        });
    }

    /// Rebuilds the cheapest move into bin `v` from each other bin if they changed: of the
    /// items elsewhere that have `v` as a candidate.
    fn refresh_in_arcs(&mut self, v: usize) {
        let (p, choice, cand_item) = (self.p, &self.choice, &self.cand_item);
        let cands = &self.bin_cands[self.bin_start[v]..self.bin_start[v + 1]];
        self.in_arcs.refresh(v, &mut self.arc_of, |list| {
            for &k2 in cands {
                let k = choice[cand_item[k2 as usize] as usize] as usize;
                if k != k2 as usize {
                    list.offer(BinArc {
                        other: p.cand_bin[k],
                        cand: k2,
                        delta: p.cand_cost[k2 as usize] - p.cand_cost[k],
                    });
                }
            }
        });
    }

    /// Moves the item of candidate `to_cand` from bin `from` to bin `to`. The out-arcs of both
    /// bins change, and the in-arcs of every candidate bin of the item.
    fn move_item(&mut self, to_cand: usize, from: u32, to: u32) {
        self.out_arcs.invalidate(from);
        self.out_arcs.invalidate(to);
        let item = self.cand_item[to_cand] as usize;
        if self.in_arcs.built() {
            for &b in &self.p.cand_bin[self.p.candidates(item)] {
                self.in_arcs.invalidate(b);
            }
        }
        // A stale cached arc would move an item that is no longer where the arc says.
        assert_eq!(
            self.p.cand_bin[self.choice[item] as usize], from,
            "stale arc"
        );
        debug_assert_eq!(self.p.cand_bin[to_cand], to);
        self.choice[item] = to_cand as u32;
        self.node[from as usize].load -= 1;
        self.node[to as usize].load += 1;
        let list = &mut self.bin_items[from as usize];
        let at = self.slot[item] as usize;
        list.swap_remove(at);
        if let Some(&other) = list.get(at) {
            self.slot[other as usize] = at as u32;
        }
        self.slot[item] = self.bin_items[to as usize].len() as u32;
        self.bin_items[to as usize].push(item as u32);
    }
}

/// The least reduced cost of any move of an item from its candidate in `choice` to another of
/// its candidates, under `prices`: non-negative when `prices` certify `choice` optimal.
fn min_reduced_cost(p: &BoundedAssignment, choice: &[u32], prices: &[f64]) -> f64 {
    (0..p.items())
        .flat_map(|i| p.candidates(i).map(move |k2| (choice[i] as usize, k2)))
        .map(|(k, k2)| {
            let (a, b) = (p.cand_bin[k] as usize, p.cand_bin[k2] as usize);
            p.cand_cost[k2] - p.cand_cost[k] - prices[a] + prices[b]
        })
        .fold(f64::INFINITY, f64::min)
}

/// An optimal assignment with prices that prove it optimal.
#[derive(Clone, Debug, PartialEq)]
pub struct Solution {
    /// The chosen candidate (a global candidate index) of every item.
    pub choice: Vec<u32>,
    /// A potential per bin under which every move of an item to another of its candidates has
    /// a non-negative reduced cost `cost(to) - cost(from) - price(from bin) + price(to bin)`:
    /// the dual certificate of `choice`, and the warm start of [`solve_from`].
    pub prices: Vec<f64>,
    /// The sink's potential: `prices` minus it are the bins' prices relative to the sink, the
    /// form [`solve_warm`] starts from.
    pub sink_price: f64,
    pub stats: FlowStats,
}

/// Solves a bounded assignment problem exactly. Returns the chosen candidate (a global
/// candidate index) of every item.
pub fn solve(p: &BoundedAssignment) -> Result<(Vec<u32>, FlowStats), Infeasible> {
    solve_priced(p).map(|s| (s.choice, s.stats))
}

/// Solves a bounded assignment problem exactly, from the cheapest candidate of every item.
pub fn solve_priced(p: &BoundedAssignment) -> Result<Solution, Infeasible> {
    repair(Network::new(p, cheapest_choice(p)))
}

/// Solves a bounded assignment problem exactly from `start`: an assignment (which may break
/// bounds) with its `prices`, which must give every move of an item a non-negative reduced cost
/// (as the prices of a [`Solution`] do for its choice on a problem with the same candidates).
/// Only the bins in conflict are repaired, so a start near the optimum solves quickly.
pub fn solve_from(p: &BoundedAssignment, start: Solution) -> Result<Solution, Infeasible> {
    assert_eq!(start.prices.len(), p.bins(), "one price per bin");
    debug_assert!(min_reduced_cost(p, &start.choice, &start.prices) >= -1e-9);
    let mut net = Network::new(p, start.choice);
    // The sink's price: every arc bin -> t with room must have a non-negative reduced cost,
    // and so must every arc t -> bin (a bin above its lower bound).
    let bins = 0..p.bins();
    let (prices, node) = (&start.prices, &net.node);
    let t = bins
        .clone()
        .filter(|&b| node[b].sink_flow < p.upper[b])
        .map(|b| prices[b]);
    let t = t.fold(f64::NEG_INFINITY, f64::max);
    let t = if t.is_finite() { t } else { 0.0 };
    debug_assert!(bins
        .filter(|&b| node[b].sink_flow > p.lower[b])
        .all(|b| prices[b] >= t));
    net.set_prices(prices, t);
    repair(net)
}

/// Solves a bounded assignment problem exactly from `prices` alone (one per bin, relative to
/// the sink's; e.g. a similar problem's [`Solution::prices`] minus its `sink_price`): every item
/// starts at its cheapest candidate under the prices, which gives every move a non-negative
/// reduced cost, and the repair only has to undo what the prices get wrong. Any prices are
/// valid; good ones leave little to repair.
pub fn solve_warm(p: &BoundedAssignment, prices: &[f64]) -> Result<Solution, Infeasible> {
    assert_eq!(prices.len(), p.bins(), "one price per bin");
    repair_from(p, priced_choice(p, prices), prices)
}

/// Repairs `start` under `prices` (one per bin, relative to the sink's), which must give every
/// move of an item a non-negative reduced cost (as [`priced_choice`] does).
fn repair_from(
    p: &BoundedAssignment,
    start: Vec<u32>,
    prices: &[f64],
) -> Result<Solution, Infeasible> {
    let mut net = Network::new(p, start);
    net.set_prices(prices, 0.0);
    repair(net)
}

/// Every item's cheapest candidate under bin `prices` (cost plus price; ties go to the first).
fn priced_choice(p: &BoundedAssignment, prices: &[f64]) -> Vec<u32> {
    (0..p.items())
        .into_par_iter()
        .with_min_len(ITEM_BLOCK)
        .map(|i| PricedCosts { p, prices }.cheapest(i) as u32)
        .collect()
}

/// Candidate costs plus their bins' prices.
#[derive(Clone, Copy)]
struct PricedCosts<'a> {
    p: &'a BoundedAssignment,
    prices: &'a [f64],
}

impl PricedCosts<'_> {
    fn of(self, k: usize) -> f64 {
        self.p.cand_cost[k] + self.prices[self.p.cand_bin[k] as usize]
    }

    /// Item `i`'s cheapest candidate (ties go to the first).
    fn cheapest(self, i: usize) -> usize {
        first_cheapest(self.p.candidates(i), |k| self.of(k))
    }
}

/// Successive shortest paths: sends every bin's excess away, then fills every bin's deficit.
fn repair(mut net: Network<'_>) -> Result<Solution, Infeasible> {
    let p = net.p;
    let bins = p.bins();
    let load = |b: usize| net.node[b].load;
    let overfull = (0..bins).filter(|&b| load(b) > p.upper[b]).count();
    let underfull = (0..bins).filter(|&b| load(b) < p.lower[b]).count();
    (net.stats.overfull_bins, net.stats.underfull_bins) = (overfull, underfull);
    for b in 0..bins {
        while net.node[b].load > net.node[b].sink_flow {
            net.push_excess(b as u32)?;
        }
    }
    for b in 0..bins {
        while net.node[b].short() {
            net.pull_deficit(b as u32)?;
        }
    }
    let sink_price = net.node[bins].potential;
    Ok(Solution {
        choice: net.choice,
        prices: net.node[..bins].iter().map(|n| n.potential).collect(),
        sink_price,
        stats: net.stats,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Builds a problem from per-item lists of (bin, cost).
    pub(super) fn problem(
        items: &[&[(u32, f64)]],
        lower: &[u32],
        upper: &[u32],
    ) -> BoundedAssignment {
        let mut p = BoundedAssignment {
            item_start: vec![0],
            lower: lower.to_vec(),
            upper: upper.to_vec(),
            ..Default::default()
        };
        for cands in items {
            for &(b, c) in *cands {
                p.cand_bin.push(b);
                p.cand_cost.push(c);
            }
            p.item_start.push(p.cand_bin.len());
        }
        p
    }

    #[test]
    fn unconstrained_items_take_their_cheapest_bin() {
        let p = problem(
            &[&[(0, 1.0), (1, 0.5)], &[(1, 2.0), (0, 3.0)]],
            &[0, 0],
            &[2, 2],
        );
        let (choice, stats) = solve(&p).unwrap();
        assert_eq!(choice, vec![1, 2]);
        assert_eq!(stats.augmentations, 0);
    }

    #[test]
    fn overfull_bin_sends_the_cheapest_item_away_through_a_chain() {
        // Both items want bin 0 (capacity 1). Moving item 1 to bin 1 costs 5; moving item 0 to
        // bin 1 costs 10, but bin 1 is full unless item 2 moves on to bin 2 at cost 1: the
        // optimum moves item 1 (extra cost 5) rather than item 0 plus item 2 (extra 10 + 1).
        let items: &[&[(u32, f64)]] = &[
            &[(0, 0.0), (1, 10.0)],
            &[(0, 0.0), (1, 5.0)],
            &[(1, 0.0), (2, 1.0)],
        ];
        let p = problem(items, &[0, 0, 0], &[1, 2, 1]);
        let (choice, stats) = solve(&p).unwrap();
        p.check(&choice).unwrap();
        assert_eq!(p.objective(&choice), 5.0);
        assert_eq!(stats.overfull_bins, 1);
        // With bin 1 capped at 1 the chain is forced: item 1 -> bin 1, item 2 -> bin 2.
        let q = problem(items, &[0, 0, 0], &[1, 1, 1]);
        let (choice, _) = solve(&q).unwrap();
        q.check(&choice).unwrap();
        assert_eq!(q.objective(&choice), 6.0);
    }

    #[test]
    fn lower_bound_pulls_an_item_back() {
        // Bin 0 must keep 1 item; the item prefers bin 1, the other item can fill bin 0 at 2.
        let p = problem(
            &[&[(0, 1.0), (1, 0.0)], &[(1, 0.0), (0, 2.0)]],
            &[1, 0],
            &[1, 2],
        );
        let (choice, stats) = solve(&p).unwrap();
        p.check(&choice).unwrap();
        assert_eq!(p.objective(&choice), 1.0);
        assert_eq!(stats.underfull_bins, 1);
    }

    /// `items` items on a ring of `bins` bins, each with candidates its own bin and the two
    /// next to it at pseudo-random costs, and loose bounds.
    fn ring(items: usize, bins: u32) -> BoundedAssignment {
        let mut seed = 12345u64;
        let mut cost = move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let cands: Vec<Vec<(u32, f64)>> = (0..items)
            .map(|i| {
                let b = i as u32 % bins;
                [b, (b + 1) % bins, (b + bins - 1) % bins]
                    .map(|b| (b, cost()))
                    .to_vec()
            })
            .collect();
        let refs: Vec<&[(u32, f64)]> = cands.iter().map(|c| c.as_slice()).collect();
        let n = bins as usize;
        problem(&refs, &vec![0; n], &vec![(items / n + 2) as u32; n])
    }

    #[test]
    fn a_warm_start_from_an_optimum_finds_the_optimum_of_tighter_bounds() {
        let p = ring(60, 12);
        let first = solve_priced(&p).unwrap();
        p.check(&first.choice).unwrap();
        assert!(
            min_reduced_cost(&p, &first.choice, &first.prices) >= -1e-12,
            "prices certify the optimum"
        );
        // Every bin keeps its load, but bin 0 gives two items to bins 5 and 6 (room for 3).
        let mut load = vec![0u32; p.bins()];
        for &k in &first.choice {
            load[p.cand_bin[k as usize] as usize] += 1;
        }
        let mut q = p.clone();
        q.lower.clone_from(&load);
        q.upper.clone_from(&load);
        (q.lower[0], q.upper[0]) = (load[0] - 2, load[0] - 2);
        q.upper[5] += 2;
        q.upper[6] += 1;
        let warm = solve_from(&q, first.clone()).unwrap();
        let (cold, _) = solve(&q).unwrap();
        q.check(&warm.choice).unwrap();
        assert_eq!(warm.stats.augmentations, 2, "one path per unit from bin 0");
        let (w, c) = (q.objective(&warm.choice), q.objective(&cold));
        assert!((w - c).abs() <= 1e-12 * c.abs(), "warm {w} vs cold {c}");
        assert!(
            w > p.objective(&first.choice),
            "the tighter problem costs more"
        );
        assert!(min_reduced_cost(&q, &warm.choice, &warm.prices) >= -1e-12);
    }

    #[test]
    fn candidate_lists_match_a_serial_count() {
        // Enough items for several blocks, and bins in more ranges than threads.
        let p = ring(3 * ITEM_BLOCK + 17, 97);
        let mut items = vec![];
        let mut by_bin = vec![vec![]; p.bins()];
        for i in 0..p.items() {
            for k in p.candidates(i) {
                items.push(i as u32);
                by_bin[p.cand_bin[k] as usize].push(k as u32);
            }
        }
        assert_eq!(item_of_candidates(&p), items);
        let (start, cands) = candidates_by_bin(&p);
        for (b, list) in by_bin.iter().enumerate() {
            assert_eq!(&cands[start[b]..start[b + 1]], list.as_slice(), "bin {b}");
        }
        assert_eq!(start[p.bins()], p.cand_bin.len());
    }

    #[test]
    fn infeasible_problems_are_reported() {
        let p = problem(&[&[(0, 0.0)], &[(0, 0.0)]], &[0], &[1]);
        assert_eq!(solve(&p), Err(Infeasible { bin: 0 }));
    }
}

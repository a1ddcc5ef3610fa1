//! The paths of sec. push_part, shared by the greedy `paths` variant ([`super::path_search`])
//! and the exact one ([`super::exact_paths`]): what a band correction reads, which way the
//! paths run, where they may start and end, and what one applied path was.

use crate::grid::{Grid, Vector};
use crate::stages::markings::{CellKind, DepthLevel, Markings};

/// The direction of the paths (sec. push_part).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PathDirection {
    /// `s_out < 0`: from surface cells into the band interface and the deep.
    In,
    /// `s_in < 0`: from band interface cells to the rest of the band and empty cells.
    Out,
}

impl PathDirection {
    /// The direction that undoes `b*`'s imbalance: out of `C_<=-R` when too many went in.
    pub fn of(s_in: i64) -> Self {
        if s_in < 0 {
            PathDirection::Out
        } else {
            PathDirection::In
        }
    }

    /// Whether a path may start in cell `c` (if it holds a particle): a surface cell for paths
    /// in, a band interface cell for paths out (of the previous markings).
    pub fn is_source(self, previous: &Markings, r: u32, c: usize) -> bool {
        previous.kind[c] == CellKind::Fluid
            && match self {
                PathDirection::In => previous.surface[c],
                PathDirection::Out => previous.level(c, r) == DepthLevel::Interface,
            }
    }

    /// Whether a path may end in the non-solid cell `c` (if it has room): a cell of
    /// `C_<=-R` for paths in, any other cell for paths out.
    pub fn is_sink(self, previous: &Markings, r: u32, c: usize) -> bool {
        let low = previous.at_or_below_interface(c, r);
        match self {
            PathDirection::In => low,
            PathDirection::Out => !low,
        }
    }
}

/// One path of alg. find that alg. update applied: cell centres from source to sink.
#[derive(Clone, Debug, Default)]
pub struct BandPath<const D: usize> {
    pub cells: Vec<Vector<D>>,
    /// Sum of `sigma_edge` along the path (eq. edge); negative when the path lowers the
    /// objective.
    pub cost: f64,
}

/// Everything a band correction reads besides the problem.
pub struct BandScene<'a, const D: usize> {
    pub grid: &'a Grid<D>,
    pub x_bar: &'a [Vector<D>],
    pub x_hat: &'a [Vector<D>],
    pub previous: &'a Markings,
    pub solid: &'a [bool],
    /// `sigma_solid_obj`'s penalty per cell (sec. 7), > 0 on `C_new_solid`.
    pub penalty: Option<&'a [f64]>,
    pub mu: u32,
}

impl<const D: usize> BandScene<'_, D> {
    /// Eq. problem3's objective of final positions in two parts: the squared displacement of
    /// the particles outside `C_new_solid`, and the penalty of those in it.
    pub fn cost_parts(&self, pos: &[Vector<D>]) -> (f64, f64) {
        let ends = pos.iter().zip(self.x_hat);
        let ends = ends.map(|(x, h)| (self.grid.cell_index_of(x), (x - h).norm_squared()));
        super::objective_parts(ends, self.penalty)
    }
}

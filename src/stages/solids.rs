//! Coupling with solids (paper sec. 7): obstacles that move through the fluid.
//!
//! An obstacle is a box or a ball rasterised to solid cells (cells whose centre it contains)
//! every step; its velocity is the pressure boundary condition (eq. solid_boundary), or zero
//! in the zero-velocity variant. The time step keeps it within one cell per step, and it stops
//! at the tank walls, static solids and other obstacles ([`Obstacle::target`]). Each step it
//! intends to move by `v dt`; the cells it would newly occupy are `C_new_solid`. How a method
//! decides whether it may move is the [`ObstacleMode`]:
//!
//! - `couple` (method ccp, sec. 7): the correction pays `sigma_solid_obj` for a particle in
//!   `C_new_solid`, `lambda_penalty` times the cell's clearing distance (def. clear_dist,
//!   eq. solid_penalty2); the obstacle moves only if no particle ends in `C_new_solid`, else it
//!   stays this step.
//! - `ignore` (the baselines' option 1): it moves regardless; particles it covers are lost
//!   volume until it passes.
//! - `naive` (option 2): it waits until the cells it would enter hold no liquid: no particle,
//!   and for narrow-band FLIP, whose deep liquid holds none, no cell of its level set's inside.

use crate::grid::active::{hull, line_hulls};
use crate::grid::{Grid, Vector};
use crate::particles::Region;
use crate::stages::markings::{Markings, SolidCells};
use std::collections::VecDeque;

/// `lambda_penalty` of eq. solid_penalty (the paper's 1000), in squared cells.
pub const PENALTY: f64 = 1000.0;

/// How far past a wall an obstacle may be without leaving the tank, cells: a shape flush with
/// a wall in metres can land an ulp past it in cells. Far below [`Obstacle::accelerate`]'s
/// probe.
const WALL_SLACK: f64 = 1e-9;

/// How obstacles treat particles in their way (scene key `simulation.obstacle`; the command
/// line's `--obstacle` takes the same names, `crate::cmd::cli`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ObstacleMode {
    /// The correction clears the cells an obstacle wants (sec. 7): method ccp's.
    Couple,
    /// An obstacle moves whatever holds its cells; the particles it covers are lost volume.
    Ignore,
    /// An obstacle stays while a cell it would enter holds liquid.
    Naive,
}

impl ObstacleMode {
    pub const ALL: [ObstacleMode; 3] = [
        ObstacleMode::Couple,
        ObstacleMode::Ignore,
        ObstacleMode::Naive,
    ];

    pub fn name(self) -> &'static str {
        match self {
            ObstacleMode::Couple => "couple",
            ObstacleMode::Ignore => "ignore",
            ObstacleMode::Naive => "naive",
        }
    }
}

/// How an obstacle's velocity evolves.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Motion {
    /// The velocity never changes (the compress and spiral lids).
    Constant,
    /// A dense object: gravity alone in the air; in the water buoyancy and linear drag, which
    /// bring its velocity to `terminal_speed` (cells per second, along gravity) at the rate
    /// `drag` (1/s): `v += (v_t - v) (1 - exp(-drag dt))`.
    Falling { terminal_speed: f64, drag: f64 },
}

/// A moving obstacle, in grid units.
#[derive(Clone, Debug, PartialEq)]
pub struct Obstacle<const D: usize> {
    pub name: String,
    /// The shape where it starts.
    pub shape: Region<D>,
    /// Displacement from the start, cells.
    pub offset: Vector<D>,
    /// Velocity, cells per second.
    pub velocity: Vector<D>,
    pub motion: Motion,
    /// The zero-velocity variant: the pressure boundary condition uses 0, so only the
    /// correction moves fluid out of the way.
    pub zero_velocity_bc: bool,
}

impl<const D: usize> Obstacle<D> {
    /// The obstacle at `offset`.
    pub fn region_at(&self, offset: &Vector<D>) -> Region<D> {
        self.shape.translated(offset)
    }

    /// Its cells at `offset`: cells whose centre it contains.
    pub fn cells_at(&self, grid: &Grid<D>, offset: &Vector<D>) -> Vec<usize> {
        let r = self.region_at(offset);
        r.cells(grid).collect()
    }

    /// The lowest point of the obstacle now (along axis 1, up), cells.
    pub fn bottom(&self) -> f64 {
        self.region_at(&self.offset).bounds().0[1]
    }

    /// Whether the obstacle at `offset` leaves the tank (by more than [`WALL_SLACK`]) or covers
    /// a cell for which `blocks` holds.
    fn hits(&self, grid: &Grid<D>, offset: &Vector<D>, blocks: &impl Fn(usize) -> bool) -> bool {
        !self.inside_tank(grid, offset) || self.region_at(offset).cells(grid).any(blocks)
    }

    /// Whether the obstacle at `offset` stays in the tank (up to [`WALL_SLACK`]), as every
    /// step leaves it.
    pub fn inside_tank(&self, grid: &Grid<D>, offset: &Vector<D>) -> bool {
        let (lo, hi) = self.region_at(offset).bounds();
        (0..D).all(|k| lo[k] >= -WALL_SLACK && hi[k] <= grid.dims[k] as f64 + WALL_SLACK)
    }

    /// Where one step at its velocity takes it: `offset + v dt`, one axis after the other, each
    /// stopped at the tank walls and short of the first cell for which `blocks` holds (static
    /// solids, other obstacles). So it slides along what stops it on one axis.
    pub fn target(&self, grid: &Grid<D>, dt: f64, blocks: impl Fn(usize) -> bool) -> Vector<D> {
        let mut at = self.offset;
        for k in 0..D {
            let (lo, hi) = self.region_at(&at).bounds();
            // A shape flush with a wall may start an ulp past it (metres to cells): no step
            // further, none back.
            let room_up = (grid.dims[k] as f64 - hi[k]).max(0.0);
            let d = (self.velocity[k] * dt).clamp(-lo[k].max(0.0), room_up);
            if d == 0.0 {
                continue;
            }
            let along = |s: f64| {
                let mut x = at;
                x[k] += d * s;
                x
            };
            // Quarter-cell samples, so that no box a cell thick skips over a blocked cell (a
            // ball may clip a corner; the end is always checked), then bisection between the
            // last sample that fits and the first that hits.
            let samples = (d.abs() * 4.0).ceil().max(1.0) as usize;
            let first_hit = (1..=samples)
                .find(|&i| self.hits(grid, &along(i as f64 / samples as f64), &blocks));
            let Some(i) = first_hit else {
                at = along(1.0);
                continue;
            };
            let (mut ok, mut bad) = ((i - 1) as f64 / samples as f64, i as f64 / samples as f64);
            for _ in 0..40 {
                let mid = (ok + bad) / 2.0;
                if self.hits(grid, &along(mid), &blocks) {
                    bad = mid;
                } else {
                    ok = mid;
                }
            }
            at = along(ok);
        }
        at
    }

    /// Updates the velocity after a step of `dt` (gravity `g`, cells/s^2), `in_water` when the
    /// obstacle touches fluid. Then it rests on what it touches: the components of its
    /// velocity that would take it into a tank wall or a cell of `fixed` (static solids) are
    /// dropped, and for a falling obstacle also those into a cell of `others` (the other
    /// obstacles). A lid of constant velocity keeps pressing on another obstacle, and goes on
    /// once that one has moved away.
    pub fn accelerate(
        &mut self,
        grid: &Grid<D>,
        g: &Vector<D>,
        dt: f64,
        in_water: bool,
        fixed: impl Fn(usize) -> bool,
        others: impl Fn(usize) -> bool,
    ) {
        let falling = match self.motion {
            Motion::Falling {
                terminal_speed,
                drag,
            } => {
                if in_water {
                    let down = g.try_normalize(0.0).unwrap_or_else(Vector::zeros);
                    let v_t = down * terminal_speed;
                    self.velocity += (v_t - self.velocity) * (1.0 - (-drag * dt).exp());
                } else {
                    self.velocity += g * dt;
                }
                true
            }
            Motion::Constant => false,
        };
        // Targets stop within 1e-10 cells of what stopped them; a probe 1e-6 cells on touches it.
        const PROBE: f64 = 1e-6;
        for k in 0..D {
            if self.velocity[k] == 0.0 {
                continue;
            }
            let mut x = self.offset;
            x[k] += PROBE * self.velocity[k].signum();
            let blocked = |c| fixed(c) || (falling && others(c));
            if self.hits(grid, &x, &blocked) {
                self.velocity[k] = 0.0;
            }
        }
    }

    /// The velocity the pressure solve sees (eq. solid_boundary).
    pub fn boundary_velocity(&self) -> Vector<D> {
        if self.zero_velocity_bc {
            Vector::zeros()
        } else {
            self.velocity
        }
    }
}

/// The solid cells of a simulation: static solids and obstacles, and how obstacles treat
/// particles.
#[derive(Clone, Debug)]
pub struct Solids<const D: usize> {
    /// Cells of the static solids.
    pub fixed: Vec<bool>,
    /// Solid cells: the static solids and the obstacles where they are now.
    pub solid: Vec<bool>,
    /// Velocity of each solid cell (zero for walls and static solids).
    pub velocity: Vec<Vector<D>>,
    /// Cells of moving obstacles (their fluid neighbours are surface).
    pub moving: Vec<bool>,
    /// Per line of cells along axis 0, the hull of its solid cells ([`SolidCells::lines`]).
    lines: Vec<[u32; 2]>,
    /// The same for the static solids alone.
    fixed_lines: Vec<[u32; 2]>,
    /// The cells the obstacles cover, where they are now (one list each).
    covered: Vec<Vec<usize>>,
    /// The obstacles, at their current offsets.
    pub obstacles: Vec<Obstacle<D>>,
    pub mode: ObstacleMode,
}

/// What the obstacles intend in one step (sec. 7).
#[derive(Clone, Debug)]
pub struct ObstaclePlan<const D: usize> {
    /// Where each would be after the step.
    targets: Vec<Vector<D>>,
    /// The cells each would newly occupy.
    wanted: Vec<Vec<usize>>,
    /// `C_new_solid` with the clearing distance of each cell (def. clear_dist).
    pub new_solid: Vec<(usize, u32)>,
    /// With `couple`: the cost of a particle in each cell (eq. solid_penalty2).
    pub penalty: Option<Vec<f64>>,
}

impl<const D: usize> Solids<D> {
    pub fn new(
        grid: &Grid<D>,
        fixed: &[Region<D>],
        obstacles: &[Obstacle<D>],
        mode: ObstacleMode,
    ) -> Self {
        let mut s = Self {
            fixed: vec![false; grid.num_cells()],
            solid: vec![],
            velocity: vec![],
            moving: vec![],
            lines: vec![],
            fixed_lines: vec![],
            covered: vec![],
            obstacles: obstacles.to_vec(),
            mode,
        };
        for r in fixed {
            r.cells(grid).for_each(|c| s.fixed[c] = true);
        }
        s.fixed_lines = line_hulls(grid, |c| s.fixed[c]);
        s.rasterise(grid);
        s
    }

    /// Solid cells, their velocities and the moving ones: the static solids plus every
    /// obstacle at its current offset.
    fn rasterise(&mut self, grid: &Grid<D>) {
        let n = grid.num_cells();
        self.solid = self.fixed.clone();
        self.velocity = vec![Vector::zeros(); n];
        self.moving = vec![false; n];
        self.covered.clear();
        self.cover(grid);
    }

    /// Marks the obstacles' cells where they are now, in order (where two overlap, the later
    /// one's velocity), over the static solids alone.
    fn cover(&mut self, grid: &Grid<D>) {
        let n0 = grid.dims[0];
        self.lines.clone_from(&self.fixed_lines);
        for o in &self.obstacles {
            let cells = o.cells_at(grid, &o.offset);
            for &c in &cells {
                self.solid[c] = true;
                self.velocity[c] = o.boundary_velocity();
                self.moving[c] = o.velocity != Vector::<D>::zeros();
                let (l, x) = (c / n0, (c % n0) as u32);
                self.lines[l] = hull(self.lines[l], [x, x + 1]);
            }
            self.covered.push(cells);
        }
    }

    /// The obstacles' cells marked again after they moved: those they covered go back to the
    /// static solids', then [`Self::cover`]. The same as rasterising the box, at the cost of
    /// the obstacles' cells.
    fn recover(&mut self, grid: &Grid<D>) {
        for c in std::mem::take(&mut self.covered).into_iter().flatten() {
            self.solid[c] = self.fixed[c];
            self.velocity[c] = Vector::zeros();
            self.moving[c] = false;
        }
        self.cover(grid);
    }

    /// Puts the obstacles at `offsets` with `velocities` (one each, in order), as a step
    /// leaves them: what a checkpoint restores.
    pub fn place(&mut self, grid: &Grid<D>, offsets: &[Vector<D>], velocities: &[Vector<D>]) {
        if self.obstacles.is_empty() {
            return;
        }
        for ((o, x), v) in self.obstacles.iter_mut().zip(offsets).zip(velocities) {
            o.offset = *x;
            o.velocity = *v;
        }
        self.rasterise(grid);
    }

    /// The cells the obstacles cover where they are now (a cell two of them cover, twice):
    /// the only cells whose solidity a step changes.
    pub fn obstacle_cells(&self) -> impl Iterator<Item = usize> + '_ {
        self.covered.iter().flatten().copied()
    }

    /// The moving obstacles' cells, when there are obstacles (without them nothing moves, and
    /// the markings need not look at every cell's neighbours).
    pub fn moving_mask(&self) -> Option<&[bool]> {
        (!self.obstacles.is_empty()).then_some(&self.moving[..])
    }

    /// The solid cells as the markings see them.
    pub fn cells(&self) -> SolidCells<'_> {
        SolidCells {
            solid: &self.solid,
            lines: &self.lines,
            moving: self.moving_mask(),
        }
    }

    /// Cells no particle may be in: every solid, or with `ignore` only the static ones
    /// (particles an obstacle covers are lost volume then, not a broken invariant).
    pub fn particle_free(&self) -> &[bool] {
        match self.mode {
            ObstacleMode::Ignore => &self.fixed,
            _ => &self.solid,
        }
    }

    /// Where each obstacle would be after a step of `dt`, and the cells it would newly occupy
    /// (`C_new_solid`) with their clearing distance. One after the other, each clear of the
    /// others where they are and where those before it go.
    pub fn plan(&self, grid: &Grid<D>, dt: f64) -> ObstaclePlan<D> {
        let mut plan = ObstaclePlan {
            targets: Vec::with_capacity(self.obstacles.len()),
            wanted: vec![],
            new_solid: vec![],
            penalty: None,
        };
        if self.obstacles.is_empty() {
            return plan;
        }
        let mut owner = Owners::of(grid, &self.obstacles);
        for (k, o) in self.obstacles.iter().enumerate() {
            let t = o.target(grid, dt, |c| {
                self.fixed[c] || owner.get(c).is_some_and(|j| j != k)
            });
            o.cells_at(grid, &t)
                .into_iter()
                .for_each(|c| owner.set(c, k));
            plan.targets.push(t);
        }
        plan.wanted = self
            .obstacles
            .iter()
            .zip(&plan.targets)
            .map(|(o, t)| {
                let mut cells = o.cells_at(grid, t);
                cells.retain(|&c| !self.solid[c]);
                cells
            })
            .collect();
        let mut new_solid: Vec<usize> = plan.wanted.iter().flatten().copied().collect();
        new_solid.sort_unstable();
        new_solid.dedup();
        let clear = clearing_distance(grid, &new_solid, &self.solid);
        plan.new_solid = new_solid.into_iter().map(|c| (c, clear[c])).collect();
        if self.mode == ObstacleMode::Couple && !plan.new_solid.is_empty() {
            plan.penalty = Some(penalties(grid.num_cells(), &plan.new_solid));
        }
        plan
    }

    /// Moves each obstacle to its target unless liquid holds cells it wants: particles (at
    /// `pos`) or, for a method whose liquid is not all particles, cells for which `liquid`
    /// holds (`couple`: after the correction; `naive`: after advection); with `ignore` it
    /// always moves. Then each obstacle's velocity is updated (gravity `g`, in the water or not
    /// by the `markings` of the step's start) and the solids rasterised again. Returns, per
    /// obstacle, whether it had to stay.
    #[allow(clippy::too_many_arguments)]
    pub fn advance(
        &mut self,
        grid: &Grid<D>,
        plan: &ObstaclePlan<D>,
        pos: &[Vector<D>],
        liquid: impl Fn(usize) -> bool,
        markings: &Markings,
        g: &Vector<D>,
        dt: f64,
    ) -> Vec<bool> {
        if self.obstacles.is_empty() {
            return vec![];
        }
        let mut occupied = vec![false; grid.num_cells()];
        for x in pos {
            occupied[grid.cell_index_of(x)] = true;
        }
        let held = |k: usize| occupied[k] || liquid(k);
        let blocked: Vec<bool> = plan
            .wanted
            .iter()
            .map(|cells| self.mode != ObstacleMode::Ignore && cells.iter().any(|&k| held(k)))
            .collect();
        // In the water: fluid in or next to a cell the obstacle occupies or wants.
        let touches_fluid = |cells: &[usize]| {
            cells.iter().any(|&k| {
                markings.is_fluid(k)
                    || grid
                        .moore_neighbors(grid.cell_coords(k))
                        .any(|m| markings.is_fluid(grid.cell_index(m)))
            })
        };
        let in_water: Vec<bool> = self
            .obstacles
            .iter()
            .zip(&plan.wanted)
            .map(|(o, w)| touches_fluid(w) || touches_fluid(&o.cells_at(grid, &o.offset)))
            .collect();
        for (o, (to, stays)) in self
            .obstacles
            .iter_mut()
            .zip(plan.targets.iter().zip(&blocked))
        {
            if !stays {
                o.offset = *to;
            }
        }
        let owner = Owners::of(grid, &self.obstacles);
        let fixed = &self.fixed;
        for (k, o) in self.obstacles.iter_mut().enumerate() {
            let others = |c: usize| owner.get(c).is_some_and(|j| j != k);
            o.accelerate(grid, g, dt, in_water[k], |c| fixed[c], others);
        }
        self.recover(grid);
        blocked
    }
}

/// Which obstacle covers each cell, if any (the later one where two overlap): a fresh zeroed
/// array written only at the obstacles' cells.
struct Owners(Vec<u32>);

impl Owners {
    /// The obstacles where they are now.
    fn of<const D: usize>(grid: &Grid<D>, obstacles: &[Obstacle<D>]) -> Self {
        let mut owner = Owners(vec![0; grid.num_cells()]);
        for (k, o) in obstacles.iter().enumerate() {
            o.region_at(&o.offset)
                .cells(grid)
                .for_each(|c| owner.set(c, k));
        }
        owner
    }

    fn get(&self, c: usize) -> Option<usize> {
        self.0[c].checked_sub(1).map(|k| k as usize)
    }

    fn set(&mut self, c: usize, k: usize) {
        self.0[c] = k as u32 + 1;
    }
}

/// The clearing distance of def. clear_dist: for each cell of `cells` (`C_new_solid`,
/// ascending), its breadth-first (von Neumann) distance from the nearest cell that is neither
/// in `cells` nor solid: 1 next to such a cell, 2 next to those, and so on. 0 elsewhere (a
/// fresh zeroed array written only at `cells`). Cells from which no such cell can be reached
/// get `u32::MAX` (nothing can clear them).
pub fn clearing_distance<const D: usize>(
    grid: &Grid<D>,
    cells: &[usize],
    solid: &[bool],
) -> Vec<u32> {
    let n = grid.num_cells();
    let mut dist = vec![0u32; n];
    let mut queue = VecDeque::new();
    let mut new_solid = vec![false; n];
    cells.iter().for_each(|&c| new_solid[c] = true);
    for &c in cells {
        dist[c] = u32::MAX;
        let free = grid
            .face_neighbors(c)
            .any(|nb| !new_solid[nb] && !solid[nb]);
        if free {
            dist[c] = 1;
            queue.push_back(c);
        }
    }
    while let Some(c) = queue.pop_front() {
        for nb in grid.face_neighbors(c) {
            if new_solid[nb] && dist[nb] == u32::MAX {
                dist[nb] = dist[c] + 1;
                queue.push_back(nb);
            }
        }
    }
    dist
}

/// The per-cell cost of a particle in `C_new_solid` (eq. solid_penalty2), from its cells and
/// their clearing distances: `lambda_penalty * cdist`, 0 elsewhere (the ordinary `sigma_obj`
/// applies there), for a grid of `n` cells (a cell nothing can clear counts `n` cells away).
pub fn penalties(n: usize, new_solid: &[(usize, u32)]) -> Vec<f64> {
    let mut penalty = vec![0.0; n];
    for &(c, d) in new_solid {
        penalty[c] = match d {
            u32::MAX => PENALTY * n as f64,
            d => PENALTY * d as f64,
        };
    }
    penalty
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clearing_distance_grows_away_from_free_cells_2d() {
        // Fig. clear_bottom: a row of new solid cells between an obstacle (solid, above) and
        // the tank floor, open to fluid at its right end only.
        let g = Grid::new([6, 3]);
        let mut solid = vec![false; 18];
        let cells: Vec<usize> = (0..5).map(|i| g.cell_index([i, 0])).collect();
        for i in 0..6 {
            solid[g.cell_index([i, 1])] = true;
        }
        let d = clearing_distance(&g, &cells, &solid);
        let row: Vec<u32> = (0..6).map(|i| d[g.cell_index([i, 0])]).collect();
        assert_eq!(row, vec![5, 4, 3, 2, 1, 0]);
        let p = penalties(18, &cells.iter().map(|&c| (c, d[c])).collect::<Vec<_>>());
        assert_eq!(p[g.cell_index([4, 0])], PENALTY);
        assert_eq!(p[g.cell_index([0, 0])], 5.0 * PENALTY);
    }

    #[test]
    fn clearing_distance_ignores_solids_and_marks_trapped_cells_3d() {
        // A 3x3x3 box of new solid cells in a 5x5x5 grid: the outer shell is 1, the centre 2.
        let g = Grid::new([5, 5, 5]);
        let solid = vec![false; 125];
        let inner = |c: usize| g.cell_coords(c).iter().all(|k| (1..4).contains(k));
        let new_solid: Vec<usize> = (0..125).filter(|&c| inner(c)).collect();
        let d = clearing_distance(&g, &new_solid, &solid);
        assert_eq!(d[g.cell_index([2, 2, 2])], 2);
        assert_eq!(d[g.cell_index([1, 2, 2])], 1);
        assert_eq!(d[g.cell_index([0, 0, 0])], 0);
        // Walled in by solids: nothing can clear it.
        let mut walls = vec![true; 125];
        walls[g.cell_index([2, 2, 2])] = false;
        let one = [g.cell_index([2, 2, 2])];
        assert_eq!(
            clearing_distance(&g, &one, &walls)[g.cell_index([2, 2, 2])],
            u32::MAX
        );
    }
}

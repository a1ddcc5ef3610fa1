//! Method nbflip's step: the hooks it implements (see the module doc of `super`).

use super::levelset::{level, surface_layer, LevelSet, March, Side};
use super::record::NbflipReport;
use super::region::{Margin, Region};
use crate::draw::{depth_level_classes, Log};
use crate::grid::active::Active;
use crate::grid::{Cell, Grid, MacField, NearCells, Vector};
use crate::methods::seam::{FluidMethod, MethodRecording, MethodReport};
use crate::particles::Particles;
use crate::snapshot::{check_elements, not_finite, Reader, SnapshotError, Writer};
use crate::stages::band::{combine_velocities, count_with_full_deep, Band};
use crate::stages::invariants::InvariantViolation;
use crate::stages::markings::{DepthLevel, Markings};
use crate::stages::solids::Solids;
use crate::stages::transfer::{self, Known};
use crate::stages::{ParticlesMut, State, StepError};
use rand::Rng;
use rayon::prelude::*;
use std::sync::Arc;

/// Layers the level set is re-marched into the liquid beyond the band: `R + 2`
/// (`extrapolateLsSimple(distance = narrowBandWidth + 2, inside = True)` in flip05_nbflip.py).
const INSIDE_LAYERS_BEYOND_BAND: u32 = 2;
/// Layers it is re-marched into the air (`extrapolateLsSimple(distance = 3)`, ibid.).
const OUTSIDE_LAYERS: u32 = 3;
/// The re-march into the air.
const OUTWARDS: March = March {
    side: Side::Outside,
    layers: OUTSIDE_LAYERS,
};
/// Particles resampling looks up at a time.
const RESAMPLING_CHUNK: usize = 1 << 16;
/// A cell holds at most this many times `mu` particles away from the surface
/// (`maxParticles = 2 minParticles`, ibid.).
const MAX_PER_MU: u32 = 2;

/// Narrow-band FLIP in a running simulation.
pub struct NbflipSim<const D: usize> {
    /// The band: particles down to `phi = -R`.
    band: Band,
    /// Whether the level set is worked on near the surface only (or on the whole grid).
    narrow: bool,
    /// The level set of the current markings (shared with the step's report).
    phi: Arc<LevelSet>,
    /// The level set advected to the end of the step, before the particles are united with it,
    /// valid on `advected_over` (none before the first step).
    advected: Option<LevelSet>,
    advected_over: Region,
    /// The cells the next advection works on: around the surface and the particles.
    next: Region,
    /// The cells the last rebuild worked on.
    rebuilt: Region,
    /// [`LevelSet::remarch`]'s scratch.
    layer: Vec<u32>,
    /// Particles deleted by resampling, net of those seeded.
    not_held: isize,
    /// The first particle seeded by the last resampling (those before it passed its test).
    first_seed: usize,
    /// The moving obstacles' cells at the last rebuild, ascending
    /// ([`NbflipSim::newly_covered_liquid`]).
    obstacle_cells: Vec<usize>,
    step: NbflipReport,
}

impl<const D: usize> NbflipSim<D> {
    pub fn new(band_r: u32, narrow: bool) -> Self {
        NbflipSim {
            band: Band { r: band_r },
            narrow,
            phi: Arc::default(),
            advected: None,
            advected_over: Region::default(),
            next: Region::default(),
            rebuilt: Region::default(),
            layer: vec![],
            not_held: 0,
            first_seed: 0,
            obstacle_cells: vec![],
            step: NbflipReport::default(),
        }
    }

    /// `R` as a level-set value.
    fn r(&self) -> f64 {
        self.band.r as f64
    }

    /// The re-marches of step 4: inwards `R + 2` layers, outwards 3.
    fn marches(&self) -> [March; 2] {
        let inside = self.band.r + INSIDE_LAYERS_BEYOND_BAND;
        [
            March {
                side: Side::Inside,
                layers: inside,
            },
            OUTWARDS,
        ]
    }

    /// How far (cells, along every axis) from the surface and the particles of a rebuild the
    /// next rebuild may change the level set: the surface and the particles move at most `cfl`
    /// cells a step, the interpolation, the shrink and the particles' spheres reach a cell
    /// further each, and the re-march beyond the cells next to the surface: `R + 2` layers on
    /// the liquid's side, 3 on the other.
    fn margin(&self, cfl: f64) -> Margin {
        let [inside, outside] = self
            .marches()
            .map(|m| cfl.ceil() as usize + 3 + m.layers as usize + 1);
        Margin { inside, outside }
    }

    /// The region within the margin of `seeds`, with the level set's liquid and the solid
    /// cells (which the inward re-march passes through) on the inner side.
    fn around(&self, s: &ParticlesMut<'_, D>, seeds: impl Iterator<Item = Cell<D>>) -> Region {
        let (phi, solid) = (&self.phi.phi, &s.solids.solid);
        let inner = |c: usize| solid[c] || phi[c] < 0.0;
        Region::around(s.grid, seeds, self.margin(s.config.cfl), inner)
    }

    /// The cells around the particles, and around the obstacles, which change the solid cells
    /// the re-march reads; sided by the level set before the rebuild (a particle's sphere makes
    /// liquid within the outer margin, and the inward re-march from there reaches only liquid
    /// that was liquid before or lies within that margin).
    fn around_particles(&self, s: &ParticlesMut<'_, D>) -> Region {
        let g = s.grid;
        let obstacles = s.solids.obstacles.iter();
        let cells = s.particles.pos.iter();
        let cells = cells.map(|x| g.cell_of(x).expect("particle inside the domain"));
        let obstacle_cells = obstacles.flat_map(|o| o.cells_at(g, &o.offset));
        self.around(s, cells.chain(obstacle_cells.map(|c| g.cell_coords(c))))
    }

    /// Whether cell `c` holds liquid now, after the advection: the advected level set's inside
    /// where it was advected, the last one's elsewhere (far from the surface, where a step
    /// does not change it). Asked of cells that are not solid.
    fn liquid_after_advection(&self, g: &Grid<D>, c: usize) -> bool {
        match &self.advected {
            Some(advected) if self.advected_over.contains(g, c) => advected.phi[c] < 0.0,
            _ => self.phi.phi[c] < 0.0,
        }
    }

    /// How many cells of liquid the obstacles newly covered since the last rebuild (with
    /// `ignore`: liquid lost; with `naive` none, since an obstacle waits for liquid); keeps
    /// their cells for the next rebuild.
    fn newly_covered_liquid(&mut self, s: &ParticlesMut<'_, D>) -> usize {
        let before = std::mem::replace(&mut self.obstacle_cells, obstacle_cells(s.solids));
        if self.phi.phi.is_empty() {
            return 0; // the first rebuild: the obstacles have not moved
        }
        let newly = self.obstacle_cells.iter().copied();
        let newly = newly.filter(|c| before.binary_search(c).is_err());
        newly
            .filter(|&c| self.liquid_after_advection(s.grid, c))
            .count()
    }

    /// Step 4: the level set from the advected one (if any) and the particles, on the cells
    /// advected and those around the particles (new ones from an emitter), with the moving
    /// obstacles carved out of it ([`LevelSet::carve`]); the cells to advect next. The
    /// re-marches leave the static solids out, and their values are then extended from the
    /// cells around them ([`LevelSet::extend_into_solids`]).
    fn rebuild_level_set(&mut self, s: &ParticlesMut<'_, D>) {
        self.step.carved += self.newly_covered_liquid(s);
        let (g, solid, pos) = (s.grid, &s.solids.solid, &s.particles.pos);
        let fixed = &s.solids.fixed;
        let marches = self.marches();
        if self.advected.is_none() {
            // The first rebuild: the particles' level set, on every cell.
            self.phi = Arc::new(LevelSet::from_particles(g, pos));
        }
        let around_particles = self.narrow.then(|| self.around_particles(s));
        let phi = Arc::make_mut(&mut self.phi);
        self.rebuilt = match &mut self.advected {
            Some(advected) => {
                let cells = match &around_particles {
                    Some(around) => self.advected_over.union(g, around),
                    None => Region::all(g),
                };
                // Cells not advected this step lie far from the surface: as they are.
                for c in cells.minus(g, &self.advected_over) {
                    advected.phi[c] = phi.phi[c];
                }
                phi.unite_shrunk(g, advected, pos, &cells.cells);
                cells
            }
            None => Region::all(g),
        };
        phi.carve(g, &self.obstacle_cells, solid);
        for march in marches {
            phi.remarch(g, march, fixed, &self.rebuilt.cells, &mut self.layer);
        }
        phi.extend_into_solids(g, fixed, &self.rebuilt.cells, OUTWARDS.cap());
        self.next = match around_particles {
            Some(around) => {
                let crossing = phi.crossing(g, solid, &self.rebuilt.cells);
                let crossing = crossing.into_iter().map(|c| g.cell_coords(c));
                self.around(s, crossing).union(g, &around)
            }
            None => Region::all(g),
        };
    }

    /// Resampling against the current level set.
    fn resampling<'a>(
        &'a self,
        grid: &'a Grid<D>,
        solid: &'a [bool],
        mu: u32,
    ) -> Resampling<'a, D> {
        Resampling {
            grid,
            phi: &self.phi,
            solid,
            cells: &self.rebuilt.cells,
            r: self.r(),
            mu,
        }
    }
}

/// Step 1, the velocity combination: faces of the liquid (next to a fluid cell of `m`) with
/// particle weight inside the combine band `phi >= -(R - 1)` keep the particles' velocity `u`,
/// its other faces take the advected grid velocity `grid_u` (MantaFlow's `combineGridVel` with
/// `narrowBand = R - 1`, `thresh = 0`). Faces in the air are left to the extrapolation, as in
/// flip: a grid value kept there would gather gravity step after step, which MantaFlow avoids
/// by adding gravity to the liquid's faces only. `active` holds every fluid cell of `m`.
#[allow(clippy::too_many_arguments)]
pub fn combine<const D: usize>(
    g: &Grid<D>,
    m: &Markings,
    active: &Active<D>,
    phi: &LevelSet,
    r: f64,
    u: &mut MacField<D>,
    known: &mut Known<D>,
    grid_u: &MacField<D>,
) {
    let fluid = active.near_cells(g, |c| m.is_fluid(c));
    combine_velocities(g, u, known, grid_u, &fluid, |a, f, weighted| {
        !weighted || phi.at_face(g, a, f) < -(r - 1.0)
    });
}

/// The moving obstacles' cells, ascending, each once.
fn obstacle_cells<const D: usize>(solids: &Solids<D>) -> Vec<usize> {
    let mut cells: Vec<usize> = solids.obstacle_cells().collect();
    cells.sort_unstable();
    cells.dedup();
    cells
}

impl<const D: usize> FluidMethod<D> for NbflipSim<D> {
    fn start(&mut self, s: &mut State<D>) {
        let keep = self.before_markings(s.particles_mut());
        s.remark(keep.as_ref());
        // The first resampling thins the seeded liquid to the band: not part of step 1.
        self.step = NbflipReport::default();
    }

    /// Cells deeper than the band count as full: emitters must not fill the deep.
    fn emitter_count(&self, s: &State<D>, c: usize) -> u32 {
        let level = level::<D>(&self.phi, &s.solids.solid, self.r(), c);
        count_with_full_deep(&s.markings, s.config.mu(), level, c)
    }

    fn particles_not_held(&self) -> isize {
        self.not_held
    }

    /// The level set's inside after the advection: `naive` obstacles wait for it as for a
    /// particle, since most of the liquid holds none.
    fn holds_liquid(&self, grid: &Grid<D>, c: usize) -> bool {
        self.liquid_after_advection(grid, c)
    }

    /// The level set, the cells the next advection works on, the count resampling deleted,
    /// and whether a level set was advected yet. The advected level set's values are not
    /// kept: the next step writes every cell of it that it reads (the cells it advects, and
    /// the others of the rebuild's region from `phi`), so it only needs to exist.
    fn save_state<'a>(&'a self, w: &mut Writer<'a>) {
        w.slice("nbflip.phi", &self.phi.phi);
        w.scalar("nbflip.advected", self.advected.is_some() as u8);
        w.bools("nbflip.next_tiles", self.next.tiles());
        w.scalar("nbflip.not_held", self.not_held as i64);
    }

    fn restore_state(&mut self, s: &State<D>, r: &Reader) -> Result<(), SnapshotError> {
        let n = Some(s.grid.num_cells());
        let phi = r.slice("nbflip.phi", n)?;
        check_elements("nbflip.phi", &phi, not_finite)?;
        self.phi = Arc::new(LevelSet { phi });
        self.advected = match r.scalar::<u8>("nbflip.advected")? {
            0 => None,
            _ => Some((*self.phi).clone()),
        };
        let tiles = r.bools("nbflip.next_tiles", None)?;
        self.next = Region::of_tiles(&s.grid, tiles).ok_or_else(|| SnapshotError::Array {
            name: "nbflip.next_tiles".into(),
            reason: "not one flag per tile of the scene's grid".into(),
        })?;
        self.not_held = r.scalar::<i64>("nbflip.not_held")? as isize;
        // The obstacles are where the checkpoint's step left them, as at its last rebuild.
        self.obstacle_cells = obstacle_cells(&s.solids);
        Ok(())
    }

    /// Step 1: particle velocities to the grid, combined with the grid's ([`combine`]).
    fn particles_to_grid(&mut self, s: &State<D>) -> Result<(MacField<D>, Known<D>), StepError> {
        let (mut u, mut known) =
            transfer::particles_to_grid(&s.grid, &s.particles.pos, &s.particles.vel);
        combine(
            &s.grid,
            &s.markings,
            &s.active,
            &self.phi,
            self.r(),
            &mut u,
            &mut known,
            &s.velocity,
        );
        Ok((u, known))
    }

    /// Step 3: the level set moves with the projected velocity (near the surface), and so does
    /// the grid velocity.
    fn next_grid_velocity(&mut self, s: &State<D>, u: MacField<D>, dt: f64) -> MacField<D> {
        self.advected_over = std::mem::take(&mut self.next);
        let advected = self.advected.get_or_insert_with(|| (*self.phi).clone());
        let cells = &self.advected_over.cells;
        self.phi.advect_into(&s.grid, &u, dt, cells, advected);
        Band::advect_grid_velocity(&s.grid, &u, dt, &s.markings, &s.active)
    }

    /// Steps 4 and 5; the level set's inside stays fluid.
    fn before_markings(&mut self, s: ParticlesMut<'_, D>) -> Option<NearCells> {
        self.rebuild_level_set(&s);
        let mu = s.config.mu();
        let resampling = self.resampling(s.grid, &s.solids.solid, mu);
        let rep = resampling.run(s.particles, s.velocity, s.rng);
        self.not_held += rep.deleted() as isize - rep.seeded as isize;
        self.first_seed = s.particles.len() - rep.seeded;
        self.step.add(&rep);
        let phi = self.phi.phi.par_iter().with_min_len(crate::PAR_GRAIN);
        Some(NearCells::new(s.grid, phi.map(|&v| v < 0.0).collect()))
    }

    /// What resampling guarantees: every particle it kept lies outside the solids, inside the
    /// liquid and at most `R` below its surface, and every particle it seeded lies in a band
    /// cell below the surface layer; every such cell holds at least `mu` particles. The level
    /// set at the particles kept is interpolated in parallel; the first particle outside the
    /// band, in order, is the one reported.
    fn check_invariants(&self, s: &State<D>) -> Result<(), InvariantViolation> {
        let (g, pos, solid) = (&s.grid, &s.particles.pos, &s.solids.solid);
        let kept = pos[..self.first_seed].par_iter();
        let outside = kept
            .with_min_len(crate::PAR_GRAIN_PARTICLES)
            .map(|x| (x, solid[g.cell_index_of(x)], self.phi.interpolate(g, x)))
            .find_first(|&(_, in_solid, phi)| in_solid || !(-self.r()..=0.0).contains(&phi));
        if let Some((x, in_solid, phi)) = outside {
            let x = x.as_slice();
            return Err(InvariantViolation(match in_solid {
                true => format!("a particle at {x:?} lies in a solid cell after resampling"),
                false => format!(
                    "a particle at {x:?} has phi = {phi:.3} after resampling, outside the band [-{}, 0]",
                    self.r()
                ),
            }));
        }
        let resampling = self.resampling(g, &s.solids.solid, s.config.mu());
        let seedable = |c: usize| resampling.seedable(c);
        if let Some(x) = pos[self.first_seed..]
            .iter()
            .find(|x| !seedable(g.cell_index_of(x)))
        {
            return Err(InvariantViolation(format!(
                "a particle was seeded at {:?}, outside the band",
                x.as_slice()
            )));
        }
        let mu = s.config.mu();
        let mut cells = self.rebuilt.cells.iter().copied();
        match cells.find(|&c| seedable(c) && s.markings.count[c] < mu) {
            Some(c) => Err(InvariantViolation(format!(
                "band cell {:?} holds {} particles after resampling (mu = {mu})",
                g.cell_coords(c),
                s.markings.count[c]
            ))),
            None => Ok(()),
        }
    }

    fn finish_step(&mut self, s: &State<D>) -> Box<dyn MethodReport<D>> {
        let mut rep = std::mem::take(&mut self.step);
        rep.particles = s.particles.len();
        rep.band_r = self.band.r;
        rep.phi = Arc::clone(&self.phi);
        rep.cells_worked = self.rebuilt.cells.len();
        Box::new(rep)
    }
}

impl<const D: usize> MethodRecording<D> for NbflipSim<D> {
    fn record_setup(&self, log: &mut dyn Log<D>) {
        log.classes("world/grid/depth", &depth_level_classes());
    }

    fn is_deep(&self, s: &State<D>, c: usize) -> bool {
        let (phi, solid) = (&self.phi, &s.solids.solid);
        !phi.phi.is_empty()
            && s.markings.is_fluid(c)
            && level::<D>(phi, solid, self.r(), c) == DepthLevel::Deep
    }
}

/// Step 5, Ferstl et al.'s resampling (MantaFlow's `adjustNumber` with `narrowBand = R`,
/// `minParticles = mu`, `maxParticles = 2 mu`) against a level set.
pub struct Resampling<'a, const D: usize> {
    pub grid: &'a Grid<D>,
    pub phi: &'a LevelSet,
    /// Cells no particle is seeded in.
    pub solid: &'a [bool],
    /// The cells the level set was rebuilt on (the others lie far from the band).
    pub cells: &'a [usize],
    /// `R`, the band's depth.
    pub r: f64,
    pub mu: u32,
}

impl<const D: usize> Resampling<'_, D> {
    /// Whether cell `c` is topped up to `mu`: a liquid cell, not solid, below the surface layer
    /// and at most `R` deep.
    pub fn seedable(&self, c: usize) -> bool {
        let v = self.phi.phi[c];
        !self.solid[c] && v <= surface_layer(D) && v >= -self.r
    }

    /// Deletes particles in a solid (an `ignore` obstacle covered them: their liquid is lost),
    /// outside the liquid (`phi > 0`), deeper than `R`, or beyond `2 mu` in a cell away from
    /// the surface; then tops up every seedable cell to `mu` with particles uniformly at
    /// random in it, moving with the grid velocity `u`. The seeds go after the particles kept.
    pub fn run(&self, p: &mut Particles<D>, u: &MacField<D>, rng: &mut impl Rng) -> NbflipReport {
        let (g, mu) = (self.grid, self.mu);
        let mut rep = NbflipReport::default();
        let mut count = vec![0u32; g.num_cells()];
        let mut keep = Vec::with_capacity(p.len());
        // The level set at the particles and their cells, in parallel, a chunk at a time (the
        // first resampling sees every particle seeded: a list for all of them would add 16
        // bytes to each); then, in order, the crowding count.
        let mut found: Vec<(f64, usize)> = Vec::with_capacity(RESAMPLING_CHUNK.min(p.len()));
        for chunk in p.pos.chunks(RESAMPLING_CHUNK) {
            (chunk.par_iter().with_min_len(crate::PAR_GRAIN_PARTICLES))
                .map(|x| (self.phi.interpolate(g, x), g.cell_index_of(x)))
                .collect_into_vec(&mut found);
            for &(v, c) in &found {
                let deleted = if self.solid[c] {
                    &mut rep.covered
                } else if v > 0.0 {
                    &mut rep.outside
                } else if v < -self.r {
                    &mut rep.below
                } else if v <= surface_layer(D) && count[c] >= MAX_PER_MU * mu {
                    &mut rep.crowded
                } else {
                    count[c] += 1;
                    keep.push(true);
                    continue;
                };
                *deleted += 1;
                keep.push(false);
            }
        }
        p.retain_flagged(&keep);
        let cells = self.cells.iter().copied();
        for c in cells.filter(|&c| count[c] < mu && self.seedable(c)) {
            let corner = Vector::<D>::from_fn(|k, _| g.cell_coords(c)[k] as f64);
            for _ in count[c]..mu {
                let x = corner + Vector::<D>::from_fn(|_, _| rng.random::<f64>());
                p.push(x, u.interpolate(g, &x));
                rep.seeded += 1;
            }
        }
        rep
    }
}

//! What a method costs, measured: its memory footprint (the up-front estimate a run is admitted
//! on, [`crate::scene::memory`]; docs/benchmarks/memory.md) and its wall time per step (the
//! cost model of `cellflip report --plan`, docs/cluster.md). Each method gives its measured
//! figures through [`super::MethodType::footprint`] and [`super::MethodType::step_cost`].

/// The cells of a grid whose per-cell array of `f64` fills glibc's largest heap block (its
/// mmap threshold stops rising at 32 MiB): a larger array comes from fresh pages, resident only
/// where a step writes it (the active cells), a smaller one from the heap, resident whole.
pub const HEAP_CELLS: f64 = (32 << 20) as f64 / 8.0;

/// A method's peak memory, measured: resident bytes per grid cell, per fluid cell and per
/// particle held, the fit behind the up-front estimate ([`crate::scene::memory`]; the
/// measurements and the command that repeats them are in docs/benchmarks/memory.md).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Footprint {
    pub per_cell: f64,
    /// Per cell of the seeded liquid: what only the liquid's cells store (the pressure rows,
    /// the band's bookkeeping).
    pub per_fluid_cell: f64,
    pub per_particle: f64,
    /// Per active cell of the seeded liquid's first markings (within `stages::ACTIVE_MARGIN` of
    /// its cells, `stages::active_cells`): the fields a step writes only there once they are
    /// larger than the allocator's mmap threshold (0 but for ccp's band in 3D; the other fits
    /// count those in `per_cell`).
    pub per_active_cell: f64,
    /// Per cell up to [`HEAP_CELLS`]: the same fields while they are small enough to come from
    /// the allocator's heap, which holds them whole.
    pub per_heap_cell: f64,
    /// What a problem large enough to be solved in copies adds (none for most methods).
    pub large: Option<LargeProblem>,
    /// Which of the seeded particles the method holds.
    pub holds: Holds,
}

/// Bytes per particle held that count only from `min_particles` particles up: a solver that
/// works on copies of problems from a size on (ccp's flow solver halves a problem of 100,000
/// items or more, and without the band every particle is an item).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LargeProblem {
    pub min_particles: usize,
    pub per_particle: f64,
}

/// The particles a method holds after its start.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Holds {
    /// Every particle seeded (and emitted).
    All,
    /// Those of the cells in the top `layers` of the seeded liquid (by depth below its
    /// surface), or, if more, of that liquid at rest over the floor (and every particle
    /// emitted): the band of ccp and of narrow-band FLIP, which drop the deeper ones after
    /// holding them all at the start.
    Band {
        layers: u32,
        start: StartPeak,
        /// Bytes per particle that the settled band counts beyond the seeded one, on top of
        /// the footprint's per particle: a band that spreads as the liquid settles (a dam's
        /// column into a sheet) can outgrow that count.
        spreading: f64,
    },
}

/// The peak while a band method starts, before it drops the deep particles: bytes per
/// particle seeded (the particles and the start's own per-particle scratch) and per cell.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StartPeak {
    pub per_particle: f64,
    pub per_cell: f64,
}

impl Footprint {
    /// The footprint in `dim` dimensions of a method holding every particle, from the measured
    /// `[2D, 3D]` pairs of bytes per cell and bytes per particle.
    pub fn of(dim: usize, measured: [(f64, f64); 2]) -> Self {
        let (per_cell, per_particle) = in_dim(dim, measured);
        Self::all(per_cell, per_particle)
    }

    /// The footprint in `dim` dimensions of a band method keeping the top `layers` of the
    /// liquid, from the measured `[2D, 3D]` pairs of `[bytes per cell, per seeded fluid cell,
    /// per particle it may hold, per particle the settled band holds beyond the seeded one]`
    /// and the peak while it starts, `(per particle seeded, per cell)`.
    pub fn band(dim: usize, layers: u32, measured: [([f64; 4], (f64, f64)); 2]) -> Self {
        let ([per_cell, per_fluid_cell, per_particle, spreading], start) = in_dim(dim, measured);
        let start = StartPeak {
            per_particle: start.0,
            per_cell: start.1,
        };
        Self {
            per_cell,
            per_fluid_cell,
            per_particle,
            per_active_cell: 0.0,
            per_heap_cell: 0.0,
            large: None,
            holds: Holds::Band {
                layers,
                start,
                spreading,
            },
        }
    }

    /// The footprint of a method holding every particle, in the dimension it was measured in.
    pub fn all(per_cell: f64, per_particle: f64) -> Self {
        Self {
            per_cell,
            per_fluid_cell: 0.0,
            per_particle,
            per_active_cell: 0.0,
            per_heap_cell: 0.0,
            large: None,
            holds: Holds::All,
        }
    }

    /// This footprint in `dim` dimensions with the measured `[2D, 3D]` pairs of bytes per
    /// active cell and per cell up to [`HEAP_CELLS`].
    pub fn with_active(self, dim: usize, measured: [(f64, f64); 2]) -> Self {
        let (per_active_cell, per_heap_cell) = in_dim(dim, measured);
        Self {
            per_active_cell,
            per_heap_cell,
            ..self
        }
    }

    /// Its bytes for a grid of `cells` of which `active` are active at the start.
    pub fn cell_bytes(&self, cells: f64, fluid: f64, active: f64) -> f64 {
        self.per_cell * cells
            + self.per_fluid_cell * fluid
            + self.per_active_cell * active
            + self.per_heap_cell * cells.min(HEAP_CELLS)
    }

    /// This footprint in `dim` dimensions, plus the measured `[2D, 3D]` bytes per particle of a
    /// problem of at least `min_particles`.
    pub fn with_large(self, dim: usize, min_particles: usize, measured: [f64; 2]) -> Self {
        Self {
            large: Some(LargeProblem {
                min_particles,
                per_particle: in_dim(dim, measured),
            }),
            ..self
        }
    }

    /// Its bytes for the particles it may hold, `held` from the seeded liquid and `held_most`
    /// at the most: [`Footprint::per_particle`] each of `held_most`, plus [`Footprint::large`]'s
    /// from its size on, plus a band's spreading for those beyond `held`.
    pub fn particle_bytes(&self, held: f64, held_most: f64) -> f64 {
        let large = (self.large)
            .filter(|l| held_most >= l.min_particles as f64)
            .map_or(0.0, |l| l.per_particle);
        let spreading = match self.holds {
            Holds::All => 0.0,
            Holds::Band { spreading, .. } => spreading * (held_most - held),
        };
        (self.per_particle + large) * held_most + spreading
    }

    /// Its bytes while a band method starts, holding all `seeded` particles on a grid of
    /// `cells` (0 for a method without a band, whose footprint only grows from its start).
    pub fn start_bytes(&self, seeded: f64, cells: f64) -> f64 {
        match self.holds {
            Holds::All => 0.0,
            Holds::Band { start, .. } => start.per_particle * seeded + start.per_cell * cells,
        }
    }
}

/// A method's wall time per step on the machine its fit was measured on (2 cores), the cost
/// model of `cellflip report --plan` (docs/cluster.md, "The cost model"): nanoseconds per unit
/// of the liquid it counts and per grid cell, fitted to the whole runs of the report's default
/// and paper matrices (tools/cost-fit.py).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepCost {
    pub ns_per_unit: f64,
    pub ns_per_cell: f64,
    pub unit: Unit,
    /// Whether the driven share of the liquid (an emitter's jet, a liquid under a moving lid)
    /// counts twice: the methods whose per-step solve iterates on the liquid (ccp's correction,
    /// Power PIC's Sinkhorn, narrow-band FLIP's level set) do more where it is thrown about.
    pub driven_twice: bool,
    /// The share of the liquid's units that counts when nothing moves it ([`Rest::Still`]):
    /// from its second step on, the warm-started pressure solve starts within its tolerance
    /// and takes no iteration (docs/cluster.md, "The cost model"). 1 for a method whose step
    /// costs the same whatever the liquid does.
    pub at_rest: f64,
    /// Whether its step moves particles out of solids that the pressure sees at rest
    /// ([`Rest::Entered`]: ccp's correction), so that such a liquid is not at rest to it.
    pub clears_solids: bool,
}

/// Whether anything moves a run's liquid, as its scene says before it runs: for the cost
/// model, which cannot see what the liquid does, the one case it can tell from the scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rest {
    /// An emitter, a lid, an obstacle falling into it that the pressure sees, or its own fall
    /// to its level, moves it; or the pressure solve starts cold each step.
    Moving,
    /// Nothing moves it, and the pressure solve starts warm (hydrostatic-2d).
    Still,
    /// As [`Rest::Still`] to the pressure, but an obstacle falls into it with zero-velocity
    /// boundary conditions (falling-obstacle-zero-bc-2d): only a method that clears solids
    /// of particles moves it.
    Entered,
}

/// What a method's cost counts of the liquid, on average over the run
/// ([`crate::scene::MemoryEstimate`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Unit {
    /// The particles it holds: the particle stages' work (FLIP, IDP, Power PIC's transport),
    /// and ccp's band, whose correction is most of its step: 2.25 us a band particle a step on
    /// dam-3d at 100^3 and 2.52 on drop-3d at 300^3, where a liquid cell cost 16.2 and 2.5 us
    /// (the drop's deep pool is cells without band particles; docs/results-paper/report.csv).
    Particle,
    /// The liquid's cells, whatever it holds: for a method whose step works on the liquid's
    /// cells more than on its particles (narrow-band FLIP's level set and pressure over all of
    /// the liquid while it holds particles only in the band).
    LiquidCell,
}

impl StepCost {
    /// The cost in `dim` dimensions from the fitted `[2D, 3D]` pairs of nanoseconds per
    /// particle held and per cell.
    pub fn of(dim: usize, fitted: [(f64, f64); 2]) -> Self {
        let (ns_per_unit, ns_per_cell) = in_dim(dim, fitted);
        Self {
            ns_per_unit,
            ns_per_cell,
            unit: Unit::Particle,
            driven_twice: false,
            at_rest: 1.0,
            clears_solids: false,
        }
    }

    /// This cost with `share` of the liquid's units counting on a liquid at rest.
    pub fn at_rest(self, share: f64) -> Self {
        Self {
            at_rest: share,
            ..self
        }
    }

    /// This cost for a method that clears solids of particles ([`Rest::Entered`]).
    pub fn clearing_solids(self) -> Self {
        Self {
            clears_solids: true,
            ..self
        }
    }

    /// The share of the liquid's units that counts at `rest`: [`StepCost::at_rest`] where
    /// nothing moves the liquid as far as this method goes, else all of them.
    pub fn rest_share(&self, rest: Rest) -> f64 {
        match (rest, self.clears_solids) {
            (Rest::Still, _) | (Rest::Entered, false) => self.at_rest,
            _ => 1.0,
        }
    }

    /// This cost per `unit` of the liquid instead, the driven share counting twice.
    pub fn per_driven(self, unit: Unit) -> Self {
        Self {
            unit,
            driven_twice: true,
            ..self
        }
    }

    /// Seconds per step with `units` of the liquid counted on `cells` cells.
    pub fn step_secs(&self, units: f64, cells: f64) -> f64 {
        (self.ns_per_unit * units + self.ns_per_cell * cells) * 1e-9
    }
}

/// The figure for `dim` dimensions of measured `[2D, 3D]` ones.
fn in_dim<T: Copy>(dim: usize, measured: [T; 2]) -> T {
    measured[dim.clamp(2, 3) - 2]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A still liquid counts its share for every method; one that a solid enters with
    /// zero-velocity boundary conditions only for a method that leaves the solid's particles.
    #[test]
    fn a_liquid_at_rest_counts_its_share_where_nothing_moves_it() {
        let flip = StepCost::of(2, [(1.0, 0.0), (1.0, 0.0)]).at_rest(0.5);
        let ccp = flip.clearing_solids();
        assert_eq!(
            StepCost::of(2, [(1.0, 0.0); 2]).rest_share(Rest::Still),
            1.0
        );
        for (rest, flip_share, ccp_share) in [
            (Rest::Moving, 1.0, 1.0),
            (Rest::Still, 0.5, 0.5),
            (Rest::Entered, 0.5, 1.0),
        ] {
            assert_eq!(flip.rest_share(rest), flip_share, "{rest:?}");
            assert_eq!(ccp.rest_share(rest), ccp_share, "{rest:?}");
        }
    }

    #[test]
    fn a_large_problem_counts_from_its_size_on() {
        let f = Footprint::all(0.0, 100.0).with_large(3, 1000, [0.0, 50.0]);
        assert_eq!(f.particle_bytes(999.0, 999.0), 99_900.0);
        assert_eq!(f.particle_bytes(1000.0, 1000.0), 150_000.0);
        assert_eq!(
            Footprint::all(0.0, 100.0).particle_bytes(1000.0, 1000.0),
            100_000.0
        );
    }

    /// The heap's share stops growing at [`HEAP_CELLS`]; the active cells' does not.
    #[test]
    fn cells_beyond_the_heap_cost_only_where_active() {
        let f = Footprint::all(1.0, 0.0).with_active(3, [(0.0, 0.0), (2.0, 10.0)]);
        let small = f.cell_bytes(1000.0, 0.0, 100.0);
        assert_eq!(small, 1000.0 + 2.0 * 100.0 + 10.0 * 1000.0);
        let large = f.cell_bytes(3.0 * HEAP_CELLS, 0.0, 100.0);
        assert_eq!(large, 3.0 * HEAP_CELLS + 2.0 * 100.0 + 10.0 * HEAP_CELLS);
        assert_eq!(Footprint::all(1.0, 0.0).cell_bytes(5.0, 7.0, 3.0), 5.0);
    }

    #[test]
    fn a_band_prices_what_it_may_hold_beyond_the_seeded_band() {
        let f = Footprint::band(
            3,
            3,
            [([0.0; 4], (0.0, 0.0)), ([0.0, 0.0, 10.0, 5.0], (2.0, 1.0))],
        );
        // 100 held at most, 40 of them beyond the 60 of the seeded band.
        assert_eq!(f.particle_bytes(60.0, 100.0), 10.0 * 100.0 + 5.0 * 40.0);
        assert_eq!(f.start_bytes(500.0, 30.0), 2.0 * 500.0 + 30.0);
        assert_eq!(Footprint::all(1.0, 1.0).start_bytes(500.0, 30.0), 0.0);
    }
}

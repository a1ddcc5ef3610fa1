//! Helpers shared by the integration tests.

#![allow(dead_code)]

use cellflip::scene::{Overrides, Scene};
use cellflip::sim::{Simulation, StepReport};

/// FNV-1a over the bits of what it is fed: a digest that changes with any bit of the state.
pub struct Digest(u64);

impl Default for Digest {
    fn default() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
}

impl Digest {
    pub fn bytes(&mut self, b: &[u8]) {
        for &x in b {
            self.0 ^= x as u64;
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    pub fn u64(&mut self, x: u64) {
        self.bytes(&x.to_le_bytes());
    }
    pub fn f64(&mut self, x: f64) {
        self.u64(x.to_bits());
    }
    pub fn hex(&self) -> String {
        format!("{:016x}", self.0)
    }
}

/// Feeds the whole state after a step: particles, markings, obstacles, clocks and counts.
pub fn digest_state<const D: usize>(d: &mut Digest, sim: &Simulation<D>) {
    for (x, v) in sim.particles.pos.iter().zip(&sim.particles.vel) {
        x.iter().chain(v.iter()).for_each(|c| d.f64(*c));
    }
    let m = &sim.markings;
    for c in 0..m.kind.len() {
        d.u64(m.kind[c] as u64);
        d.u64(m.count[c] as u64);
        d.u64(m.surface[c] as u64);
        d.u64(m.depth[c] as u64);
    }
    for o in &sim.obstacles {
        o.offset.iter().chain(o.velocity.iter()).for_each(|c| d.f64(*c));
    }
    d.f64(sim.time_secs);
    d.u64(sim.steps);
    d.u64(sim.total_particles as u64);
    d.f64(sim.target_volume);
    d.u64(sim.n_deep as u64);
}

/// Feeds a step's report, all but its timings.
pub fn digest_report<const D: usize>(d: &mut Digest, rep: &StepReport<D>) {
    d.f64(rep.dt_secs);
    d.u64(rep.dt_shortened as u64);
    d.u64(rep.pcg.iterations as u64);
    d.f64(rep.pcg.residual);
    d.f64(rep.max_speed);
    d.u64(rep.emitted as u64);
    d.f64(rep.volume_percent);
    if let Some(c) = &rep.correction {
        d.f64(c.objective);
        d.u64(c.overfull_before as u64);
        d.u64(c.augmentations as u64);
        d.u64(c.fallback.is_some() as u64);
        for (a, b) in &c.moves {
            a.iter().chain(b.iter()).for_each(|x| d.f64(*x));
        }
        if let Some(b) = &c.band {
            for v in [b.alpha, b.n_in as i64, b.n_out as i64, b.s_in, b.s_out] {
                d.u64(v as u64);
            }
            d.u64(b.n_move as u64);
            d.u64(b.paths_applied as u64);
            d.u64(b.find_calls as u64);
            d.f64(b.first_objective);
            d.f64(b.objective);
            d.u64(b.net_in as u64);
            d.u64(b.failure.is_some() as u64);
        }
    }
    if let Some(x) = &rep.deep {
        for v in [x.removed, x.added, x.unplaced, x.deep_cells, x.interface_cells] {
            d.u64(v as u64);
        }
    }
    rep.blocked.iter().for_each(|b| d.u64(*b as u64));
    for (c, k) in &rep.new_solid {
        d.u64(*c as u64);
        d.u64(*k as u64);
    }
}

/// The digest of `steps` steps of a scene: state and report after every step, chained.
pub fn digest_run<const D: usize>(scene: &Scene, steps: u64) -> String {
    let mut sim = Simulation::<D>::new(scene.config::<D>());
    let mut d = Digest::default();
    digest_state(&mut d, &sim);
    for _ in 0..steps {
        let rep = sim
            .step()
            .unwrap_or_else(|e| panic!("{} step {}: {e}", scene.name(), sim.steps + 1));
        digest_report(&mut d, &rep);
        digest_state(&mut d, &sim);
    }
    d.hex()
}

pub fn load(name: &str, o: &Overrides) -> Scene {
    Scene::load(name, o).unwrap_or_else(|e| panic!("{name}: {e:#}"))
}

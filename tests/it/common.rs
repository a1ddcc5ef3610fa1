//! Helpers shared by the integration tests: loading scenes, the one step loop (through the
//! program's own runner), the golden digest, recordings read back, and the program run as a
//! command.

#![allow(dead_code)]

use cellflip::methods::ccp::BandMode;
use cellflip::methods::ccp::CcpReport;
use cellflip::methods::idp::IdpReport;
use cellflip::methods::{MethodFlags, MethodKind};
use cellflip::runner::{Limit, Runner};
use cellflip::scene::{Overrides, Scene};
use cellflip::step::{Simulation, StepReport};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn load(name: &str, o: &Overrides) -> Scene {
    Scene::load(name, o).unwrap_or_else(|e| panic!("{name}: {e:#}"))
}

/// Overrides of the method and the band.
pub fn with(method: MethodKind, band: Option<BandMode>) -> Overrides {
    Overrides {
        method: Some(method),
        flags: band_flags(band),
        ..Default::default()
    }
}

/// `--band` when `band` is given.
pub fn band_flags(band: Option<BandMode>) -> MethodFlags {
    let flags = MethodFlags::default();
    band.map_or(flags.clone(), |b| flags.with("band", b))
}

/// A new simulation of `scene` with its method, and ccp's `--cross-check` when `cross_check`.
pub fn simulation<const D: usize>(scene: &Scene, cross_check: bool) -> Simulation<D> {
    let mut method = scene.method.clone();
    method.ccp.cross_check = cross_check;
    Simulation::new(scene.config::<D>(), &method)
}

/// Steps `sim` until `limit` with the program's runner (the invariants are checked inside
/// every step); `check` sees the simulation and the report after each step. Panics naming the
/// step when a step fails.
pub fn run_sim<const D: usize>(
    sim: Simulation<D>,
    limit: Limit,
    mut check: impl FnMut(&Simulation<D>, &StepReport<D>),
) -> Runner<D> {
    let mut runner = Runner::new(sim);
    runner
        .run(
            limit,
            || false,
            |sim, rep| {
                check(sim, rep);
                Ok::<_, anyhow::Error>(())
            },
        )
        .unwrap_or_else(|e| panic!("{e:#}"));
    runner
}

/// [`run_sim`] that returns a failed step's error instead of panicking.
pub fn try_run_sim<const D: usize>(
    sim: Simulation<D>,
    limit: Limit,
    mut check: impl FnMut(&Simulation<D>, &StepReport<D>),
) -> anyhow::Result<()> {
    Runner::new(sim).run(
        limit,
        || false,
        |sim, rep| {
            check(sim, rep);
            Ok(())
        },
    )
}

/// Runs a tank at rest for `steps` steps, checking after every step that the volume is 100 %
/// and whatever `check` checks; returns the runner and the fastest particle speed seen
/// (cells/s).
pub fn run_at_rest<const D: usize>(
    scene: &Scene,
    steps: u64,
    mut check: impl FnMut(&StepReport<D>, &str),
) -> (Runner<D>, f64) {
    let mut fastest = 0.0f64;
    let runner = run::<D>(scene, Some(steps), |sim, rep| {
        let v = &sim.state.particles.vel;
        fastest = v.iter().map(|v| v.norm()).fold(fastest, f64::max);
        let at = format!("{D}D step {}", sim.state.steps);
        let volume = rep.volume_percent;
        assert!((volume - 100.0).abs() < 1e-9, "{at}: volume {volume} %");
        check(rep, &at);
    });
    (runner, fastest)
}

/// [`run_sim`] on a scene, for `steps` steps or (`None`) the scene's duration.
pub fn run<const D: usize>(
    scene: &Scene,
    steps: Option<u64>,
    check: impl FnMut(&Simulation<D>, &StepReport<D>),
) -> Runner<D> {
    let limit = steps.map_or(Limit::SimSeconds(scene.duration_secs()), Limit::Steps);
    run_sim(simulation::<D>(scene, false), limit, check)
}

/// The report of method ccp.
pub fn ccp<const D: usize>(rep: &StepReport<D>) -> &CcpReport<D> {
    rep.method_report::<CcpReport<D>>().expect("a ccp report")
}

/// The report of method idp.
pub fn idp<const D: usize>(rep: &StepReport<D>) -> &IdpReport<D> {
    rep.method_report::<IdpReport<D>>().expect("an idp report")
}

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
    let s = &sim.state;
    for (x, v) in s.particles.pos.iter().zip(&s.particles.vel) {
        x.iter().chain(v.iter()).for_each(|c| d.f64(*c));
    }
    let m = &s.markings;
    for c in 0..m.kind.len() {
        d.u64(m.kind[c] as u64);
        d.u64(m.count[c] as u64);
        d.u64(m.surface[c] as u64);
        d.u64(m.depth(c) as u64);
    }
    for o in &s.solids.obstacles {
        o.offset
            .iter()
            .chain(o.velocity.iter())
            .for_each(|c| d.f64(*c));
    }
    d.f64(s.time_secs);
    d.u64(s.steps);
    d.u64(s.total_particles as u64);
    d.f64(s.target_volume);
    d.u64(sim.method.particles_not_held() as u64);
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
    if let Some(r) = rep.method_report::<CcpReport<D>>() {
        let c = &r.correction;
        d.f64(c.objective);
        d.f64(c.penalty);
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
        if let Some(x) = &r.deep {
            for v in [
                x.removed,
                x.added,
                x.unplaced,
                x.deep_cells,
                x.interface_cells,
            ] {
                d.u64(v as u64);
            }
        }
    }
    rep.blocked.iter().for_each(|b| d.u64(*b as u64));
    for (c, k) in &rep.new_solid {
        d.u64(*c as u64);
        d.u64(*k as u64);
    }
}

/// The digest of `steps` steps of a scene: state and report after every step, chained; and
/// the PCG iterations of all its pressure solves (idp's second solves included), so that a
/// solver regression reads as a number, not only as a changed digest.
pub fn digest_run<const D: usize>(scene: &Scene, steps: u64) -> (String, usize) {
    let mut d = Digest::default();
    let mut iterations = 0;
    digest_state(&mut d, &simulation::<D>(scene, false));
    run::<D>(scene, Some(steps), |sim, rep| {
        iterations += rep.pcg.iterations;
        if let Some(idp) = rep.method_report::<IdpReport<D>>() {
            iterations += idp.pcg.iterations;
        }
        digest_report(&mut d, rep);
        digest_state(&mut d, sim);
    });
    (d.hex(), iterations)
}

/// Every entity path of a recording.
pub fn logged_entities(path: &Path) -> BTreeSet<String> {
    use rerun::external::re_log_encoding::DecoderApp;
    use rerun::log::{Chunk, LogMsg};
    let reader = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let mut out = BTreeSet::new();
    for msg in DecoderApp::decode_lazy(reader) {
        if let LogMsg::ArrowMsg(store, arrow) = msg.unwrap() {
            if store.kind() == rerun::StoreKind::Recording {
                let chunk = Chunk::from_arrow_msg(&arrow).unwrap();
                out.insert(
                    chunk
                        .entity_path()
                        .to_string()
                        .trim_start_matches('/')
                        .to_string(),
                );
            }
        }
    }
    out
}

/// The entity paths docs/recordings.md documents (`<name>` placeholders kept).
pub fn documented_entities() -> Vec<String> {
    let page = include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/recordings.md"));
    crate::docs::first_column(page, "| entity | when | what |")
}

/// Whether a logged path matches a documented one, where `<...>` stands for one path part.
pub fn matches(documented: &str, logged: &str) -> bool {
    let (d, l): (Vec<&str>, Vec<&str>) =
        (documented.split('/').collect(), logged.split('/').collect());
    d.len() == l.len()
        && d.iter()
            .zip(&l)
            .all(|(a, b)| a == b || (a.starts_with('<') && a.ends_with('>')))
}

/// The chunks of one kind of store (the recording or its blueprint) in a recording file.
pub fn chunks(path: &Path, kind: rerun::StoreKind) -> Vec<rerun::log::Chunk> {
    use rerun::external::re_log_encoding::DecoderApp;
    use rerun::log::{Chunk, LogMsg};
    let reader = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let mut out = vec![];
    for msg in DecoderApp::decode_lazy(reader) {
        if let LogMsg::ArrowMsg(store, arrow) = msg.unwrap() {
            if store.kind() == kind {
                out.push(Chunk::from_arrow_msg(&arrow).unwrap());
            }
        }
    }
    out
}

/// A view of a recording's blueprint, as read back from the file.
#[derive(Debug, Default, Clone)]
pub struct ReadView {
    /// `2D`, `3D`, `TimeSeries`, `TextLog`, `TextDocument`.
    pub class: String,
    pub name: String,
    pub origin: String,
    /// Its query lines (`+ path`, `- path`).
    pub queries: Vec<String>,
    /// Its background's kind (`BackgroundKind` as a number: 1 gradient dark, 2 gradient
    /// bright, 3 solid colour) and colour (RGBA), if set.
    pub background: Option<(u8, Option<u32>)>,
}

/// The views of a recording's blueprint, and the state of each side panel (`blueprint_panel`,
/// `selection_panel`, `time_panel`) as its `PanelState` number (2 = collapsed).
pub fn blueprint(path: &Path) -> (Vec<ReadView>, std::collections::BTreeMap<String, u8>) {
    use rerun::external::re_sdk_types::blueprint::archetypes as bp;
    let mut views: std::collections::BTreeMap<String, ReadView> = Default::default();
    let mut panels = std::collections::BTreeMap::new();
    let text = |c: &rerun::log::Chunk, d: rerun::ComponentDescriptor| -> Vec<String> {
        c.iter_slices::<String>(d.component)
            .flatten()
            .map(|s| s.to_string())
            .collect()
    };
    for c in chunks(path, rerun::StoreKind::Blueprint) {
        let entity = c.entity_path().to_string();
        let parts: Vec<&str> = entity.trim_start_matches('/').split('/').collect();
        match parts.as_slice() {
            ["view", id] => {
                let v = views.entry(id.to_string()).or_default();
                v.class = text(&c, bp::ViewBlueprint::descriptor_class_identifier()).concat();
                v.name = text(&c, bp::ViewBlueprint::descriptor_display_name()).concat();
                v.origin = text(&c, bp::ViewBlueprint::descriptor_space_origin()).concat();
            }
            ["view", id, "ViewContents"] => {
                views.entry(id.to_string()).or_default().queries =
                    text(&c, bp::ViewContents::descriptor_query());
            }
            ["view", id, "Background"] => {
                let kind = bp::Background::descriptor_kind().component;
                let color = bp::Background::descriptor_color().component;
                let kind = c.iter_slices::<u8>(kind).flatten().copied().next();
                let color = c.iter_slices::<u32>(color).flatten().copied().next();
                views.entry(id.to_string()).or_default().background = kind.map(|k| (k, color));
            }
            [panel @ ("blueprint_panel" | "selection_panel" | "time_panel")] => {
                let d = match *panel {
                    "time_panel" => bp::TimePanelBlueprint::descriptor_state().component,
                    _ => bp::PanelBlueprint::descriptor_state().component,
                };
                let state = c.iter_slices::<u8>(d).flatten().copied().next();
                panels.insert(panel.to_string(), state.unwrap_or(0));
            }
            _ => {}
        }
    }
    (views.into_values().collect(), panels)
}

/// Per step, how many 2D arrows `entity` holds.
pub fn arrows_2d_per_step(path: &Path, entity: &str) -> Vec<(i64, usize)> {
    per_step(path, entity, |c| {
        let d = "Arrows2D:vectors".into();
        c.iter_slices::<[f32; 2]>(d).map(|s| s.len()).collect()
    })
}

/// Per step, the values of the scalar `entity`.
pub fn scalars_per_step(path: &Path, entity: &str) -> Vec<(i64, f64)> {
    scalars_on(path, entity, "step")
}

/// The values of the scalar `entity` on `timeline` (`sim_time` in nanoseconds).
pub fn scalars_on(path: &Path, entity: &str, timeline: &str) -> Vec<(i64, f64)> {
    on_timeline(path, entity, timeline, |c| {
        let d = "Scalars:scalars".into();
        c.iter_slices::<f64>(d).map(|s| s[0]).collect()
    })
}

fn per_step<T>(
    path: &Path,
    entity: &str,
    values: impl Fn(&rerun::log::Chunk) -> Vec<T>,
) -> Vec<(i64, T)> {
    on_timeline(path, entity, "step", values)
}

/// What `values` reads from each row of `entity`, with the row's time on `timeline`.
pub fn on_timeline<T>(
    path: &Path,
    entity: &str,
    timeline: &str,
    values: impl Fn(&rerun::log::Chunk) -> Vec<T>,
) -> Vec<(i64, T)> {
    let mut out = vec![];
    for c in chunks(path, rerun::StoreKind::Recording) {
        if c.entity_path().to_string().trim_start_matches('/') != entity {
            continue;
        }
        let name: &'static str = match timeline {
            "step" => "step",
            "sim_time" => "sim_time",
            t => panic!("cellflip records no timeline '{t}'"),
        };
        // Static rows (a series' colour and name) have no time.
        let Some(times) = c.timelines().get(&name.into()) else {
            continue;
        };
        let steps = times.times_raw().to_vec();
        out.extend(steps.into_iter().zip(values(&c)));
    }
    out.sort_by_key(|(s, _)| *s);
    out
}

/// A scratch folder for one test, `<temp>/cellflip-<kind>-<pid>-<test>`: created empty, removed
/// with everything in it when dropped (also when the test fails), so that test runs leave no
/// files behind.
pub struct Scratch(PathBuf);

impl Scratch {
    pub fn new(kind: &str, test: &str) -> Scratch {
        let d = std::env::temp_dir().join(format!("cellflip-{kind}-{}-{test}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        Scratch(d)
    }
}

impl std::ops::Deref for Scratch {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// `cellflip args` run from the package folder.
pub fn cellflip(args: &[&str]) -> Output {
    cellflip_in(Path::new("."), args)
}

/// `cellflip args` run from the folder `dir`.
pub fn cellflip_in(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_cellflip"))
        .args(args)
        .current_dir(dir)
        .env_remove("RERUN")
        .output()
        .expect("the binary runs")
}

/// Asserts that a `cellflip` process succeeded, showing its standard error if not.
pub fn ok(out: &Output) {
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The scratch folder of a command-line test.
pub fn scratch_dir(test: &str) -> Scratch {
    Scratch::new("test", test)
}

//! The recording's default layout (its blueprint), built as plain data from what the run has
//! (issue 15, items 1, 5 and 7).
//!
//! The world view takes most of the window; side panels start collapsed. On the right: the
//! volume, then tabs of time-series panels with one quantity family each (its own axis, a
//! legend only when it has several series), then tabs with the legend, the log and the scene.
//! Panels exist only for what the run logs (band, cross-check, obstacles, the method). Layers
//! that would hide or blend with the particles get views of their own (band levels, IDP's
//! density error, Power PIC's image; in 3D the markings are hidden in the 3D view and shown in
//! the slice).
//!
//! [`super::blueprint`] writes it into the recording.

use super::{Drawing, Plane};
use crate::draw::{LayerView, Needs, Panel};
use crate::methods::MethodInfo;
use crate::scene::Scene;

/// What a run has, which decides the layout.
#[derive(Debug)]
pub struct RunFacts<'a> {
    pub dims: Vec<usize>,
    pub method: &'a MethodInfo,
    pub band: bool,
    pub cross_check: bool,
    pub obstacles: Vec<String>,
    /// 3D: the axis the slice cuts across.
    pub slice_axis: usize,
    /// 3D: the liquid's surface is drawn (`world/surface`), so the particles start hidden.
    pub surface: bool,
}

impl<'a> RunFacts<'a> {
    /// What a run of `scene` drawn as `drawing` has.
    pub fn of(scene: &'a Scene, drawing: &Drawing) -> Self {
        Self {
            dims: scene.dims.clone(),
            method: scene.method.kind.info(),
            band: scene.method.band().is_some(),
            cross_check: scene.method.cross_checks(),
            obstacles: scene.file.obstacle.iter().map(|o| o.name.clone()).collect(),
            slice_axis: drawing.slice.0,
            surface: drawing.surface,
        }
    }

    /// Whether one of the method's layer views this run has shows `entity`.
    pub fn shows(&self, entity: &str) -> bool {
        let mut views = self.method.layer_views.iter().filter(|l| self.has(l.needs));
        views.any(|l| l.layers.contains(&entity))
    }

    fn has(&self, needs: Needs) -> bool {
        match needs {
            Needs::Always => true,
            Needs::Band => self.band,
            Needs::CrossCheck => self.cross_check,
            Needs::Obstacles => !self.obstacles.is_empty(),
        }
    }
}

/// The panels of every run.
const COMMON_PANELS: &[Panel] = &[
    Panel {
        title: "particles",
        series: &["metrics/particles"],
        needs: Needs::Always,
    },
    Panel {
        title: "time step dt (s)",
        series: &["metrics/dt"],
        needs: Needs::Always,
    },
    Panel {
        title: "max speed (m/s)",
        series: &["metrics/max_speed"],
        needs: Needs::Always,
    },
    Panel {
        title: "stage times (ms)",
        series: &["metrics/time/**"],
        needs: Needs::Always,
    },
    Panel {
        title: "pressure: PCG iterations",
        series: &["metrics/pcg/iterations"],
        needs: Needs::Always,
    },
    Panel {
        title: "pressure: PCG residual",
        series: &["metrics/pcg/residual"],
        needs: Needs::Always,
    },
];

/// The kinds of view the layout uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Spatial2D,
    Spatial3D,
    TimeSeries,
    TextLog,
    TextDocument,
}

/// One view: what it shows and how it starts.
#[derive(Debug)]
pub struct View {
    pub kind: Kind,
    pub name: String,
    pub origin: String,
    /// Query lines (`+ path`, `- path`, `/**` for a subtree).
    pub contents: Vec<String>,
    /// Entities it draws but hides until the user switches them on.
    pub hidden: Vec<String>,
    /// Time series: whether the legend shows (several series).
    pub legend: bool,
    /// 3D: where the eye starts and what it looks at (world coordinates).
    pub eye: Option<([f32; 3], [f32; 3])>,
    /// 2D: the region it starts showing, `[x0, x1, y0, y1]` (world coordinates).
    pub bounds: Option<[f32; 4]>,
}

impl View {
    fn new(kind: Kind, name: &str, origin: &str, contents: Vec<String>) -> Self {
        Self {
            kind,
            name: name.to_string(),
            origin: origin.to_string(),
            contents,
            hidden: vec![],
            legend: false,
            eye: None,
            bounds: None,
        }
    }

    fn series(p: &Panel, obstacles: &[String]) -> Self {
        let contents: Vec<String> = p
            .series
            .iter()
            .flat_map(|s| match s.split_once("/<name>/") {
                Some((a, b)) => obstacles.iter().map(|o| format!("+ {a}/{o}/{b}")).collect(),
                None => vec![format!("+ {s}")],
            })
            .collect();
        let mut v = View::new(Kind::TimeSeries, p.title, "/", contents);
        v.legend = v.contents.len() > 1 || v.contents.iter().any(|c| c.ends_with("/**"));
        v
    }
}

/// A layout: containers (rows, columns with their shares; tabs) and views.
#[derive(Debug)]
pub enum Pane {
    Row(Vec<(f32, Pane)>),
    Column(Vec<(f32, Pane)>),
    Tabs(Vec<Pane>),
    /// Equal cells, as square as the viewer can make them.
    Grid(Vec<Pane>),
    View(View),
}

impl Pane {
    /// Tabs, or the one pane when there is one.
    fn tabs(mut panes: Vec<Pane>) -> Pane {
        if panes.len() == 1 {
            panes.remove(0)
        } else {
            Pane::Tabs(panes)
        }
    }
}

/// The obstacles' panels: one per quantity, every obstacle a series.
const OBSTACLE_PANELS: &[Panel] = &[
    Panel {
        title: "obstacles: lowest point (m)",
        series: &["metrics/obstacle/<name>/height"],
        needs: Needs::Obstacles,
    },
    Panel {
        title: "obstacles: speed (m/s)",
        series: &["metrics/obstacle/<name>/speed"],
        needs: Needs::Obstacles,
    },
    Panel {
        title: "obstacles: blocked (1 = had to stay)",
        series: &["metrics/obstacle/<name>/blocked"],
        needs: Needs::Obstacles,
    },
];

/// The layout of a run: world (and its layer views) on the left, the series, legend, log and
/// scene on the right.
pub fn layout(f: &RunFacts<'_>) -> Pane {
    let series = |panels: &[Panel]| -> Vec<Pane> {
        panels
            .iter()
            .filter(|p| f.has(p.needs))
            .map(|p| Pane::View(View::series(p, &f.obstacles)))
            .collect()
    };
    let volume = Panel {
        title: "volume (% of V*)",
        series: &["metrics/volume_percent"],
        needs: Needs::Always,
    };
    let mut method = series(OBSTACLE_PANELS);
    method.extend(series(f.method.panels));
    let mut right = vec![
        (1.0, Pane::View(View::series(&volume, &[]))),
        (1.4, Pane::Tabs(series(COMMON_PANELS))),
    ];
    if !method.is_empty() {
        right.push((1.4, Pane::tabs(method)));
    }
    let log = View::new(Kind::TextLog, "log", "log", vec!["+ log".into()]);
    right.push((
        1.4,
        Pane::Tabs(vec![
            Pane::View(View::new(
                Kind::TextDocument,
                "legend",
                "legend",
                vec!["+ legend".into()],
            )),
            Pane::View(log),
            Pane::View(View::new(
                Kind::TextDocument,
                "scene",
                "scene",
                vec!["+ scene".into()],
            )),
        ]),
    ));
    Pane::Row(vec![(2.4, world_column(f)), (1.0, Pane::Column(right))])
}

/// The world view, largest, with the layer views beside it in tabs. The world view leaves
/// the layer views' cell layers out (2D) or hidden until switched on (3D, with the markings
/// and the moved-particle highlight); in 3D every layer view shows the slice.
fn world_column(f: &RunFacts<'_>) -> Pane {
    let three_d = f.dims.len() == 3;
    let layer_views = f.method.layer_views.iter().filter(|l| f.has(l.needs));
    let (in_world, apart): (Vec<&LayerView>, Vec<&LayerView>) =
        layer_views.partition(|l| l.origin == "world");
    let bounds = world_bounds(f);
    let world = world_view(f, "world", "");
    // Where the layer views draw: the world plane in 2D, the slice in 3D.
    let (origin, on_plane): (&str, fn(&str) -> String) = match three_d {
        true => ("slice", |e| e.replacen("world/", "slice/", 1)),
        false => ("world", |e| e.to_string()),
    };
    let mut slice = View::new(Kind::Spatial2D, "slice", "slice", vec!["+ slice/**".into()]);
    slice.bounds = bounds;
    let mut tabs: Vec<Pane> = vec![];
    for l in &in_world {
        let shown = l.layers.iter().chain(l.marks);
        let mut contents: Vec<String> = shown.map(|e| format!("+ {}", on_plane(e))).collect();
        if !three_d {
            contents.push("+ world/domain".into());
        }
        let layers = l.layers.iter().map(|e| format!("- {}", on_plane(e)));
        slice.contents.extend(layers);
        let mut v = View::new(Kind::Spatial2D, l.title, origin, contents);
        v.bounds = bounds;
        tabs.push(Pane::View(v));
    }
    for l in &apart {
        let contents = l.layers.iter().chain(l.marks).map(|e| format!("+ {e}"));
        tabs.push(Pane::View(View::new(
            Kind::Spatial2D,
            l.title,
            l.origin,
            contents.collect(),
        )));
    }
    if three_d {
        tabs.insert(0, Pane::View(slice));
        Pane::Row(vec![(1.0, Pane::View(world)), (1.0, Pane::tabs(tabs))])
    } else {
        tabs.insert(0, Pane::View(world));
        Pane::tabs(tabs)
    }
}

/// One run of a comparison: its label (a path part), its title and what it has.
pub struct Compared<'a> {
    pub label: String,
    pub title: String,
    pub facts: RunFacts<'a>,
}

/// The layout of `cellflip compare`: every run's world in a grid, each under its label and
/// with the same camera; beside them the volume, the kinetic energy and (with obstacles) each
/// obstacle's height, a line per run; the legend and every run's log in tabs.
pub fn compare_layout(runs: &[Compared<'_>], obstacles: &[String]) -> Pane {
    let worlds = runs
        .iter()
        .map(|r| Pane::View(world_view(&r.facts, &r.title, &format!("{}/", r.label))))
        .collect();
    let lines = |title: &str, series: &dyn Fn(&str) -> Vec<String>| {
        let contents = runs
            .iter()
            .flat_map(|r| series(&r.label))
            .map(|p| format!("+ {p}"))
            .collect();
        let mut v = View::new(Kind::TimeSeries, title, "/", contents);
        v.legend = true;
        Pane::View(v)
    };
    let mut right = vec![
        (
            1.0,
            lines("volume (% of V*)", &|l| {
                vec![format!("{l}/metrics/volume_percent")]
            }),
        ),
        (
            1.0,
            lines("kinetic energy per unit mass (m^2/s^2)", &|l| {
                vec![format!("{l}/metrics/kinetic_energy")]
            }),
        ),
    ];
    if !obstacles.is_empty() {
        let height = |l: &str| {
            let names = obstacles.iter();
            names
                .map(|o| format!("{l}/metrics/obstacle/{o}/height"))
                .collect()
        };
        right.push((1.0, lines("obstacles: lowest point (m)", &height)));
    }
    let logs = runs.iter().map(|r| format!("+ {}/log", r.label)).collect();
    right.push((
        1.0,
        Pane::Tabs(vec![
            Pane::View(View::new(Kind::TextLog, "log", "/", logs)),
            Pane::View(View::new(
                Kind::TextDocument,
                "legend",
                "legend",
                vec!["+ legend".into()],
            )),
        ]),
    ));
    Pane::Row(vec![(2.6, Pane::Grid(worlds)), (1.0, Pane::Column(right))])
}

/// What the 2D world (or the 3D slice) spans, for a 2D view's bounds.
fn world_bounds(f: &RunFacts<'_>) -> Option<[f32; 4]> {
    let plane = match f.dims.len() {
        3 => Plane::slice(&f.dims, f.slice_axis, 0),
        _ => Plane::world_2d(&f.dims),
    };
    Some([0.0, plane.cols as f32, 0.0, plane.rows as f32])
}

/// The world view of a run whose paths start with `prefix` (empty, or `<label>/`): in 3D the
/// markings, the moved-particle highlight and the method's cell layers hidden until switched
/// on, in 2D the cell layers left to their own views.
fn world_view(f: &RunFacts<'_>, name: &str, prefix: &str) -> View {
    let layer_views = f.method.layer_views.iter().filter(|l| f.has(l.needs));
    let in_world = layer_views.filter(|l| l.origin == "world");
    let cell_layers = in_world.flat_map(|l| l.layers.iter().map(|e| format!("{prefix}{e}")));
    let kind = match f.dims.len() {
        3 => Kind::Spatial3D,
        _ => Kind::Spatial2D,
    };
    let origin = format!("{prefix}world");
    let mut world = View::new(kind, name, &origin, vec![format!("+ {origin}/**")]);
    if kind == Kind::Spatial3D {
        world.hidden = ["world/grid/markings", "world/corrector/moved"]
            .map(|e| format!("{prefix}{e}"))
            .into();
        if f.surface {
            world.hidden.push(format!("{prefix}world/particles"));
        }
        world.hidden.extend(cell_layers);
        world.eye = Some(eye(&f.dims));
    } else {
        world.contents.extend(cell_layers.map(|e| format!("- {e}")));
        world.bounds = world_bounds(f);
    }
    world
}

/// A 3D eye that frames the tank: in front of it (+z), a little above and to the right, far
/// enough to see it whole, looking at its centre.
fn eye(dims: &[usize]) -> ([f32; 3], [f32; 3]) {
    let centre: [f32; 3] = std::array::from_fn(|k| dims[k] as f32 / 2.0);
    let size = dims.iter().copied().max().unwrap_or(1) as f32;
    let position = [
        centre[0] + 0.6 * size,
        centre[1] + 0.5 * size,
        centre[2] + 2.2 * size,
    ];
    (position, centre)
}

//! What the colours of a recording mean: the one table of each layer's classes and colours,
//! from which both the recording's annotation contexts and its on-screen legend (a markdown
//! panel, `legend`) are made (issue 15, items 2 and 3).
//!
//! Every layer a view shows at once draws opaque colours that mean one thing: the cell markings
//! (paper sec. markings) under the particles in the world view; the band levels (sec.
//! band_method, `def.depth`) in their own view. The deep, whose particles are imaginary, is its
//! own class in the markings (not a bubble) and has the same colour as the deep band level.

use crate::stages::markings::{CellKind, DepthLevel, Markings};

/// The markings layer's class ids (one byte per cell): a cell's kind, surface and fill as a
/// recording draws them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum MarkingClass {
    Empty = 0,
    Surface = 1,
    Inner = 2,
    /// An inner cell holding fewer than `mu` particles (def. bubble).
    Bubble = 3,
    Solid = 4,
}

impl MarkingClass {
    pub const ALL: [MarkingClass; 5] = [
        MarkingClass::Empty,
        MarkingClass::Surface,
        MarkingClass::Inner,
        MarkingClass::Bubble,
        MarkingClass::Solid,
    ];

    /// Cell `c`'s class in `markings` with `mu` particles per full cell.
    pub fn of(markings: &Markings, c: usize, mu: u32) -> Self {
        match markings.kind[c] {
            CellKind::Empty => MarkingClass::Empty,
            CellKind::Solid => MarkingClass::Solid,
            CellKind::Fluid if markings.surface[c] => MarkingClass::Surface,
            CellKind::Fluid if markings.count[c] < mu => MarkingClass::Bubble,
            CellKind::Fluid => MarkingClass::Inner,
        }
    }

    pub fn label(self) -> &'static str {
        match self {
            MarkingClass::Empty => "empty",
            MarkingClass::Surface => "surface",
            MarkingClass::Inner => "inner",
            MarkingClass::Bubble => "bubble",
            MarkingClass::Solid => "solid",
        }
    }
}

/// A class of a cell layer: its id in the layer's images or points, label and colour (RGBA).
pub type Class = (u16, &'static str, [u8; 4]);

/// The class id of the deep in the markings layer (the marking classes take 0 to 4).
pub const DEEP: u16 = 5;

const DEEP_COLOR: [u8; 4] = [130, 70, 180, 255];

/// The markings layer: the paper's cell classes, and the deep of the band methods.
pub fn marking_classes() -> Vec<Class> {
    let mut classes: Vec<Class> = MarkingClass::ALL
        .iter()
        .map(|k| {
            let rgba = match k {
                MarkingClass::Empty => [0, 0, 0, 0],
                MarkingClass::Surface => [50, 150, 70, 255],
                MarkingClass::Inner => [58, 58, 66, 255],
                MarkingClass::Bubble => [220, 50, 50, 255],
                MarkingClass::Solid => [150, 150, 150, 255],
            };
            (*k as u16, k.label(), rgba)
        })
        .collect();
    classes.push((DEEP, "deep", DEEP_COLOR));
    classes
}

/// The band levels (sec. band_method) as classes: label and colour of each [`DepthLevel`].
pub fn depth_level_classes() -> Vec<Class> {
    DepthLevel::ALL
        .iter()
        .map(|l| {
            let rgba = match l {
                DepthLevel::NotFluid => [0, 0, 0, 0],
                DepthLevel::Surface => [50, 150, 70, 255],
                DepthLevel::Band => [110, 180, 235, 255],
                DepthLevel::Interface => [240, 200, 40, 255],
                DepthLevel::Deep => DEEP_COLOR,
            };
            (*l as u16, l.label(), rgba)
        })
        .collect()
}

/// What each marking class means, for the legend.
fn marking_meaning(id: u16) -> &'static str {
    match id {
        0 => "no fluid (drawn transparent)",
        1 => "fluid cell next to an empty one",
        2 => "fluid cell holding `mu` particles",
        3 => "fluid cell below the surface holding fewer than `mu`",
        4 => "wall or obstacle",
        _ => "band method: below the band, its particles are imaginary (`n_deep`)",
    }
}

/// The particles' speed ramp: stops as `(fraction of the speed bound, colour)`.
const SPEED_STOPS: [(f64, [u8; 3]); 3] = [
    (0.0, [40, 90, 230]),
    (0.5, [40, 210, 255]),
    (1.0, [255, 255, 255]),
];

/// A particle's colour: dark blue at rest, through cyan, to white at `max`.
pub fn speed_color(speed: f64, max: f64) -> [u8; 3] {
    let s = (speed / max).clamp(0.0, 1.0);
    let k = if s < SPEED_STOPS[1].0 { 0 } else { 1 };
    let ((s0, a), (s1, b)) = (SPEED_STOPS[k], SPEED_STOPS[k + 1]);
    let t = (s - s0) / (s1 - s0);
    std::array::from_fn(|i| (a[i] as f64 + (b[i] as f64 - a[i] as f64) * t) as u8)
}

/// The correction's moves and the particles they moved.
pub const MOVE_COLOR: [u8; 3] = [255, 60, 200];
/// Obstacles, their trails and the cells they want.
pub const OBSTACLE_COLOR: [u8; 3] = [230, 90, 40];
/// The liquid's surface in 3D (`world/surface`): water blue, lighter than the particles at rest.
pub const SURFACE_COLOR: [u8; 3] = [90, 160, 235];
pub const NEW_SOLID_COLOR: [u8; 3] = [255, 200, 0];

/// The name of the colour nearest to `c`, for the legend (markdown cannot colour text, and
/// the viewer's font has no colour emoji).
fn colour_name(c: [u8; 3]) -> &'static str {
    const NAMES: [(&str, [u8; 3]); 12] = [
        ("red", [220, 50, 50]),
        ("orange", [235, 110, 40]),
        ("yellow", [240, 205, 40]),
        ("green", [50, 150, 70]),
        ("light blue", [110, 180, 235]),
        ("cyan", [40, 210, 255]),
        ("blue", [40, 90, 230]),
        ("purple", [130, 70, 180]),
        ("magenta", [255, 60, 200]),
        ("grey", [150, 150, 150]),
        ("dark grey", [58, 58, 66]),
        ("white", [255, 255, 255]),
    ];
    let d = |a: [u8; 3]| {
        (0..3)
            .map(|i| (a[i] as i32 - c[i] as i32).pow(2))
            .sum::<i32>()
    };
    NAMES
        .iter()
        .min_by_key(|(_, a)| d(*a))
        .map_or("", |(s, _)| s)
}

fn row(rgb: [u8; 3], name: &str, meaning: &str) -> String {
    let hex = format!("#{:02x}{:02x}{:02x}", rgb[0], rgb[1], rgb[2]);
    format!("| {} `{hex}` | {name} | {meaning} |\n", colour_name(rgb))
}

/// The legend panel's markdown: the particles' speed ramp (`max_speed_ms`, the speed bound in
/// m/s), the cell markings (with the deep when `band`), the band levels when `band`, and the
/// correction's and obstacles' marks.
pub fn markdown(max_speed_ms: f64, band: bool) -> String {
    let head = "| colour | what | meaning |\n|---|---|---|\n";
    let mut s = format!("### Particles: speed\n\n{head}");
    for (f, c) in SPEED_STOPS {
        s += &row(
            c,
            &format!("{:.2} m/s", f * max_speed_ms),
            "particle speed (ramp between)",
        );
    }
    s += &format!("\n### Cells: markings (world view)\n\n{head}");
    for (id, label, c) in marking_classes() {
        if id != MarkingClass::Empty as u16 && (band || id != DEEP) {
            s += &row([c[0], c[1], c[2]], label, marking_meaning(id));
        }
    }
    if band {
        s += &format!("\n### Cells: band levels (band view)\n\n{head}");
        for (id, label, c) in depth_level_classes() {
            if id != DepthLevel::NotFluid as u16 {
                s += &row([c[0], c[1], c[2]], label, "depth level (`def.depth`)");
            }
        }
    }
    s += &format!("\n### Marks\n\n{head}");
    s += &row(
        MOVE_COLOR,
        "moves",
        "the correction sent a particle to another cell (`--moves`)",
    );
    s += &row(
        [60, 200, 80],
        "paths (band)",
        "a band path that lowers the objective (red: raises it)",
    );
    s += &row(OBSTACLE_COLOR, "obstacle", "an obstacle, its trail");
    s += &row(
        NEW_SOLID_COLOR,
        "new solid",
        "cells an obstacle wants (`C_new_solid`)",
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_deep_cell_short_of_mu_is_a_bubble_3d() {
        // A 3x3x3 box of single particles but its corner (2, 2, 2): cell (0, 0, 0) is inner.
        let g = crate::grid::Grid::new([3, 3, 3]);
        let corner = g.cell_index([2, 2, 2]);
        let pos: Vec<_> = (0..27)
            .filter(|&c| c != corner)
            .map(|c| g.center(g.cell_coords(c)))
            .collect();
        let m = Markings::compute(&g, &pos, &[false; 27]);
        let c = g.cell_index([0, 0, 0]);
        assert_eq!(MarkingClass::of(&m, c, 2), MarkingClass::Bubble);
        assert_eq!(MarkingClass::of(&m, c, 1), MarkingClass::Inner);
    }

    #[test]
    fn the_speed_ramp_runs_from_its_first_stop_to_its_last() {
        assert_eq!(speed_color(0.0, 2.0), SPEED_STOPS[0].1);
        assert_eq!(speed_color(1.0, 2.0), SPEED_STOPS[1].1);
        assert_eq!(speed_color(9.0, 2.0), SPEED_STOPS[2].1);
    }

    #[test]
    fn every_visible_colour_of_a_layer_means_one_class() {
        for table in [marking_classes(), depth_level_classes()] {
            let visible: Vec<[u8; 4]> = table.iter().map(|c| c.2).filter(|c| c[3] > 0).collect();
            for (i, a) in visible.iter().enumerate() {
                assert!(visible[i + 1..].iter().all(|b| b != a), "{table:?}");
            }
        }
    }

    #[test]
    fn the_legend_names_every_class_it_draws() {
        let md = markdown(2.0, true);
        for (_, label, _) in marking_classes().iter().skip(1) {
            assert!(md.contains(&format!("| {label} |")), "{label} in\n{md}");
        }
        assert!(md.contains("| band interface |") && md.contains("2.00 m/s"));
        assert!(!markdown(2.0, false).contains("| deep |"));
    }
}

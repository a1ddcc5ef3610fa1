//! The drawing vocabulary: what a method says it records, in words that name no recording
//! library. A method describes its time-series panels ([`Panel`]), its layers that need views
//! of their own ([`LayerView`]) and draws its state through the [`Log`] trait; the recorder
//! (`crate::record`, the only module that imports rerun) implements [`Log`] and lays the
//! views out. [`legend`] is the one table of every layer's classes and colours.

pub mod legend;

pub use legend::depth_level_classes;

use crate::grid::Vector;

/// What a method may log and draw, in grid units; implemented by the recorder's [`Canvas`].
pub trait Log<const D: usize> {
    /// A scalar time series, every step.
    fn scalar(&mut self, path: &str, value: f64);
    /// A warning in the log, prefixed with the step.
    fn warn(&mut self, message: &str);
    /// Class ids with their labels and colours (RGBA) for `path` and below, logged once.
    fn classes(&mut self, path: &str, classes: &[(u16, &'static str, [u8; 4])]);
    /// One class id per cell: in 2D an image over the grid, in 3D points at the centres of the
    /// cells whose class is not in `hidden_3d` (and the image of the slice).
    fn cell_classes(
        &mut self,
        path: &str,
        class: &dyn Fn(usize) -> u8,
        hidden_3d: &[u8],
        layer: Layer,
    );
    /// An image of values in `range` (see [`Image`]), drawn with a colour map in its own 2D
    /// view (a [`LayerView`] of the method).
    fn image(&mut self, path: &str, image: &Image, range: [f32; 2]);
    /// Arrows from the first point to the second of each pair (an empty batch clears).
    fn arrows(&mut self, path: &str, from_to: &[(Vector<D>, Vector<D>)], style: Style);
    /// Line strips through points, each with its colour and label (an empty batch clears).
    fn strips(
        &mut self,
        path: &str,
        strips: &[Vec<Vector<D>>],
        colors: &[[u8; 3]],
        labels: Vec<String>,
        style: Style,
    );
    /// The correction's moves `(x_hat, x)`: one arrow each under `world/corrector/moves`
    /// (from `x_hat` to `x`, or with `--moves hops` from the centre of `x_hat`'s cell to the
    /// centre of `x`'s), and the moved particles highlighted under `world/corrector/moved`.
    fn moves(&mut self, from_to: &[(Vector<D>, Vector<D>)]);
}

/// A plane of per-cell values for [`Log::image`]: `[width, height]`, row 0 at the bottom.
#[derive(Clone, Debug, Default)]
pub struct Image {
    pub size: [usize; 2],
    pub values: Vec<f32>,
}

impl Image {
    /// `value` of every cell of a grid of `dims` cells: the whole grid in 2D, the layer through
    /// the middle of the third axis in 3D.
    pub fn of_cells<const D: usize>(dims: [usize; D], value: impl Fn(usize) -> f32) -> Self {
        let (w, h) = (dims[0], dims[1]);
        let offset = if D == 3 { dims[2] / 2 * w * h } else { 0 };
        Self {
            size: [w, h],
            values: (offset..offset + w * h).map(value).collect(),
        }
    }
}

/// How a drawing looks: its colour, radius (cells) and, in 2D, its draw order.
#[derive(Clone, Copy, Debug)]
pub struct Style {
    pub color: [u8; 3],
    pub radius: f32,
    pub order: f32,
}

/// How a layer of cells is drawn: its draw order in 2D, its points' radius in 3D (cells).
#[derive(Clone, Copy, Debug)]
pub struct Layer {
    pub order: f32,
    pub radius_3d: f32,
}

/// When a panel or view belongs in the layout.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Needs {
    Always,
    /// The band method (ccp `--band`).
    Band,
    /// `--cross-check`.
    CrossCheck,
    /// The scene has obstacles.
    Obstacles,
}

/// A time-series panel: one quantity family on one axis.
#[derive(Debug)]
pub struct Panel {
    pub title: &'static str,
    /// The scalar entities it plots (`/**` for all below).
    pub series: &'static [&'static str],
    pub needs: Needs,
}

/// A spatial view of cell layers the world view leaves out (they would hide or blend with the
/// particles): its title, origin, the layers, and the marks drawn over them here as in the
/// world view.
#[derive(Debug)]
pub struct LayerView {
    pub title: &'static str,
    pub origin: &'static str,
    pub layers: &'static [&'static str],
    pub marks: &'static [&'static str],
    pub needs: Needs,
}

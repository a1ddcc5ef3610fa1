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
        Self {
            size: [dims[0], dims[1]],
            values: Self::layer(dims).map(value).collect(),
        }
    }

    /// [`Self::of_cells`] of a value given at some cells alone: `value(k)` at `cells[k]`
    /// (ascending), 0 at the others; the work is per listed cell, not per cell of the grid.
    pub fn of_listed_cells<const D: usize>(
        dims: [usize; D],
        cells: &[u32],
        value: impl Fn(usize) -> f32,
    ) -> Self {
        let layer = Self::layer(dims);
        let mut image = Self {
            size: [dims[0], dims[1]],
            values: vec![0.0; layer.len()],
        };
        let first = cells.partition_point(|&c| (c as usize) < layer.start);
        for (k, &c) in cells.iter().enumerate().skip(first) {
            match image.values.get_mut(c as usize - layer.start) {
                Some(v) => *v = value(k),
                None => break,
            }
        }
        image
    }

    /// The cells drawn of a grid of `dims`: every one in 2D, the layer through the middle of
    /// the third axis in 3D.
    fn layer<const D: usize>(dims: [usize; D]) -> std::ops::Range<usize> {
        let (w, h) = (dims[0], dims[1]);
        let offset = if D == 3 { dims[2] / 2 * w * h } else { 0 };
        offset..offset + w * h
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_image_of_listed_cells_is_the_image_of_their_values_and_zero_elsewhere_2d_and_3d() {
        // Every third cell listed, valued by its place in the list; the 3D layer is the one
        // through the middle of the third axis, so listed cells below and above it are skipped.
        fn check<const D: usize>(dims: [usize; D]) {
            let n: usize = dims.iter().product();
            let cells: Vec<u32> = (0..n as u32).filter(|c| c % 3 == 1).collect();
            let value = |k: usize| 1.0 + k as f32;
            let listed = Image::of_listed_cells(dims, &cells, value);
            let whole = Image::of_cells(dims, |c| match cells.binary_search(&(c as u32)) {
                Ok(k) => value(k),
                Err(_) => 0.0,
            });
            assert_eq!(listed.size, whole.size);
            assert_eq!(listed.values, whole.values, "{D}D");
            assert!(listed.values.iter().any(|&v| v > 0.0));
        }
        check([7, 5]);
        check([7, 5, 4]);
        check([6, 4, 3]);
    }
}

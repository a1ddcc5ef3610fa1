//! Drawing on a recording at one step, in 2D or 3D, through one [`Plane`] abstraction.
//!
//! World units are cells. A 2D world is drawn as an image (x right, rows down): positions are
//! logged as `(x, ny - y)`, so gravity points down the screen and each particle lies over its
//! cell of the `world/grid/markings` image. In 3D, y is up (`RIGHT_HAND_Y_UP`), and everything
//! drawn under `world/` but the obstacles is also drawn, cut to one layer of cells, on the slice
//! plane under `slice/` (issue 15, item 5): a 2D image of the classes with the particles, moves
//! and paths that lie in that layer, so what happens inside the fluid can be seen.

use super::Stream;
use crate::draw::legend::MOVE_COLOR;
use crate::draw::{Image, Layer, Log, Style};
use crate::grid::{Grid, Vector};

/// A plane of cells drawn as an image: cell axis `u` to the right, `v` up, `cols` x `rows`
/// cells; in 3D it cuts the layer of cells `layer` across `axis`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Plane {
    pub u: usize,
    pub v: usize,
    pub cols: usize,
    pub rows: usize,
    pub cut: Option<(usize, usize)>,
}

impl Plane {
    /// The 2D world: x right, y up.
    pub fn world_2d(dims: &[usize]) -> Self {
        Self {
            u: 0,
            v: 1,
            cols: dims[0],
            rows: dims[1],
            cut: None,
        }
    }

    /// The slice of a 3D grid across `axis` through cell layer `layer`: y up (z up across y),
    /// the remaining axis to the right.
    pub fn slice(dims: &[usize], axis: usize, layer: usize) -> Self {
        let v = if axis == 1 { 2 } else { 1 };
        let u = 3 - axis - v;
        Self {
            u,
            v,
            cols: dims[u],
            rows: dims[v],
            cut: Some((axis, layer)),
        }
    }

    /// Image coordinates of a point (cells).
    fn at<const D: usize>(&self, x: &Vector<D>) -> [f32; 2] {
        [x[self.u] as f32, self.rows as f32 - x[self.v] as f32]
    }

    /// Whether a point lies in the plane's layer of cells.
    fn holds<const D: usize>(&self, x: &Vector<D>) -> bool {
        self.cut.is_none_or(|(a, k)| x[a].floor() == k as f64)
    }

    /// The cell under pixel `(col, row)` of the plane's image.
    fn cell<const D: usize>(&self, col: usize, row: usize) -> [usize; D] {
        std::array::from_fn(|k| match k {
            _ if k == self.u => col,
            _ if k == self.v => self.rows - 1 - row,
            _ => self.cut.map_or(0, |(_, layer)| layer),
        })
    }
}

/// How points look: radius (cells), draw order in 2D, labels.
pub(super) struct PointLook {
    pub radius: f32,
    pub order: f32,
    pub labels: Option<Vec<String>>,
}

/// Draws on the recording at one step, in 2D or 3D; keeps the first error.
pub struct Canvas<'a, const D: usize> {
    pub(super) rec: &'a Stream,
    pub(super) dims: [usize; D],
    pub(super) step: u64,
    /// Draw the correction's moves as cell hops (`--moves hops`).
    pub(super) hops: bool,
    /// 3D: the slice plane.
    pub(super) slice: Option<Plane>,
    pub(super) result: rerun::RecordingStreamResult<()>,
}

impl<const D: usize> Canvas<'_, D> {
    pub(super) fn keep(&mut self, r: rerun::RecordingStreamResult<()>) {
        if self.result.is_ok() {
            self.result = r;
        }
    }

    /// World coordinates of a point in cells: in 2D rows down, `(x, ny - y, 0)`.
    pub(super) fn world(&self, x: &Vector<D>) -> [f32; 3] {
        if D == 2 {
            let p = Plane::world_2d(&self.dims).at(x);
            [p[0], p[1], 0.0]
        } else {
            [x[0] as f32, x[1] as f32, x[2] as f32]
        }
    }

    fn world_all(&self, xs: &[Vector<D>]) -> Vec<[f32; 3]> {
        xs.iter().map(|x| self.world(x)).collect()
    }

    /// Where a 2D drawing of `path` goes: the world plane in 2D; in 3D the slice, under
    /// `slice/` (obstacles are not cut).
    fn plane_of(&self, path: &str) -> Option<(Plane, String)> {
        if D == 2 {
            return Some((Plane::world_2d(&self.dims), path.to_string()));
        }
        let rest = path.strip_prefix("world/")?;
        (!rest.starts_with("obstacles")).then_some(())?;
        self.slice.map(|p| (p, format!("slice/{rest}")))
    }

    pub(super) fn text(&mut self, msg: &str, level: &'static str) {
        let r = self
            .rec
            .log("log", &rerun::TextLog::new(msg).with_level(level));
        self.keep(r);
    }

    /// Points with one colour each (or one for all), one radius, and labels if given.
    pub(super) fn points(
        &mut self,
        path: &str,
        xs: &[Vector<D>],
        colors: Vec<[u8; 3]>,
        look: PointLook,
    ) {
        if D == 3 {
            let mut pts = rerun::Points3D::new(self.world_all(xs))
                .with_colors(colors.clone())
                .with_radii([look.radius]);
            if let Some(l) = look.labels.clone() {
                pts = pts.with_labels(l);
            }
            let r = self.rec.log(path, &pts);
            self.keep(r);
        }
        let Some((plane, path)) = self.plane_of(path) else {
            return;
        };
        let inside: Vec<usize> = (0..xs.len()).filter(|&i| plane.holds(&xs[i])).collect();
        let pick = |v: &[[u8; 3]]| -> Vec<[u8; 3]> {
            if v.len() == xs.len() {
                inside.iter().map(|&i| v[i]).collect()
            } else {
                v.to_vec()
            }
        };
        let mut pts = rerun::Points2D::new(inside.iter().map(|&i| plane.at(&xs[i])))
            .with_colors(pick(&colors))
            .with_radii([look.radius])
            .with_draw_order(look.order);
        if let Some(l) = look.labels {
            pts = pts.with_labels(inside.iter().map(|&i| l[i].clone()));
        }
        let r = self.rec.log(path, &pts);
        self.keep(r);
    }

    /// An axis-aligned box from `lo` to `hi` (cells): the tank (`domain`: static, 3D as a
    /// wireframe, under everything in 2D) or an obstacle (per step, over the particles).
    pub(super) fn boxes(
        &mut self,
        path: &str,
        lo: &Vector<D>,
        hi: &Vector<D>,
        color: [u8; 3],
        domain: bool,
    ) {
        let (a, b) = (self.world(lo), self.world(hi));
        let centre: [f32; 3] = std::array::from_fn(|k| (a[k] + b[k]) / 2.0);
        let half: [f32; 3] = std::array::from_fn(|k| (b[k] - a[k]).abs() / 2.0);
        let r = match (D, domain) {
            (2, _) => {
                let b = rerun::Boxes2D::from_centers_and_half_sizes(
                    [(centre[0], centre[1])],
                    [(half[0], half[1])],
                )
                .with_colors([color]);
                if domain {
                    self.rec.log_static(path, &b)
                } else {
                    self.rec.log(path, &b.with_draw_order(25.0))
                }
            }
            (_, true) => {
                let b = rerun::Boxes3D::from_centers_and_half_sizes([centre], [half])
                    .with_colors([color])
                    .with_fill_mode(rerun::FillMode::MajorWireframe);
                self.rec.log_static(path, &b)
            }
            _ => {
                let b = rerun::Boxes3D::from_centers_and_half_sizes([centre], [half]);
                self.rec.log(path, &b.with_colors([color]))
            }
        };
        self.keep(r);
    }

    /// One line strip through world points.
    pub(super) fn strip_world(&mut self, path: &str, pts: &[[f32; 3]], color: [u8; 3]) {
        let r = if D == 2 {
            let strip: Vec<[f32; 2]> = pts.iter().map(|p| [p[0], p[1]]).collect();
            let s = rerun::LineStrips2D::new([strip]).with_colors([color]);
            self.rec.log(path, &s.with_draw_order(24.0))
        } else {
            let s = rerun::LineStrips3D::new([pts.to_vec()]).with_colors([color]);
            self.rec.log(path, &s)
        };
        self.keep(r);
    }

    /// One class id per cell of a plane, as a segmentation image.
    fn class_image(&mut self, path: &str, plane: Plane, class: &dyn Fn(usize) -> u8, order: f32) {
        let grid = Grid::new(self.dims);
        let mut img = Vec::with_capacity(plane.cols * plane.rows);
        for row in 0..plane.rows {
            img.extend((0..plane.cols).map(|col| class(grid.cell_index(plane.cell(col, row)))));
        }
        let size = [plane.cols as u32, plane.rows as u32];
        let format = rerun::ImageFormat::segmentation(size, rerun::ChannelDatatype::U8);
        let image = rerun::SegmentationImage::new(img, format).with_draw_order(order);
        let r = self.rec.log(path, &image);
        self.keep(r);
    }
}

impl<const D: usize> Log<D> for Canvas<'_, D> {
    fn scalar(&mut self, path: &str, value: f64) {
        let r = self.rec.log(path, &rerun::Scalars::single(value));
        self.keep(r);
    }

    fn warn(&mut self, message: &str) {
        let msg = format!("step {}: {message}", self.step);
        self.text(&msg, rerun::TextLogLevel::WARN);
    }

    fn classes(&mut self, path: &str, classes: &[(u16, &'static str, [u8; 4])]) {
        let c: Vec<(u16, &str, rerun::Rgba32)> = classes
            .iter()
            .map(|(id, l, c)| {
                (
                    *id,
                    *l,
                    rerun::Rgba32::from_unmultiplied_rgba(c[0], c[1], c[2], c[3]),
                )
            })
            .collect();
        let context = rerun::AnnotationContext::new(c);
        let r = self.rec.log_static(path, &context);
        self.keep(r);
        let slice = path
            .strip_prefix("world")
            .filter(|_| D == 3 && self.slice.is_some());
        if let Some(rest) = slice {
            let r = self.rec.log_static(format!("slice{rest}"), &context);
            self.keep(r);
        }
    }

    fn cell_classes(
        &mut self,
        path: &str,
        class: &dyn Fn(usize) -> u8,
        hidden_3d: &[u8],
        layer: Layer,
    ) {
        if D == 3 {
            let grid = Grid::new(self.dims);
            let n: usize = self.dims.iter().product();
            let (centres, ids): (Vec<[f32; 3]>, Vec<rerun::components::ClassId>) = (0..n)
                .map(|c| (c, class(c)))
                .filter(|(_, k)| !hidden_3d.contains(k))
                .map(|(c, k)| {
                    (
                        self.world(&grid.center(grid.cell_coords(c))),
                        rerun::components::ClassId::from(k as u16),
                    )
                })
                .unzip();
            let pts = rerun::Points3D::new(centres)
                .with_class_ids(ids)
                .with_radii([layer.radius_3d]);
            let r = self.rec.log(path, &pts);
            self.keep(r);
        }
        if let Some((plane, path)) = self.plane_of(path) {
            self.class_image(&path, plane, class, layer.order);
        }
    }

    fn image(&mut self, path: &str, image: &Image, range: [f32; 2]) {
        let ([w, h], values) = (image.size, &image.values);
        // Image row 0 is the top.
        let mut bytes = Vec::with_capacity(4 * w * h);
        for row in (0..h).rev() {
            for v in &values[row * w..(row + 1) * w] {
                bytes.extend_from_slice(&v.to_le_bytes());
            }
        }
        let format = rerun::ImageFormat::depth([w as u32, h as u32], rerun::ChannelDatatype::F32);
        let image = rerun::DepthImage::new(bytes, format)
            .with_colormap(rerun::components::Colormap::Viridis)
            .with_depth_range([range[0] as f64, range[1] as f64]);
        let r = self.rec.log(path, &image);
        self.keep(r);
    }

    fn arrows(&mut self, path: &str, from_to: &[(Vector<D>, Vector<D>)], style: Style) {
        if D == 3 {
            let origins = from_to.iter().map(|(a, _)| self.world(a));
            let vectors = from_to.iter().map(|(a, b)| {
                let (a, b) = (self.world(a), self.world(b));
                [b[0] - a[0], b[1] - a[1], b[2] - a[2]]
            });
            let a = rerun::Arrows3D::from_vectors(vectors).with_origins(origins);
            let r = self.rec.log(
                path,
                &a.with_colors([style.color]).with_radii([style.radius]),
            );
            self.keep(r);
        }
        let Some((plane, path)) = self.plane_of(path) else {
            return;
        };
        let inside = from_to
            .iter()
            .filter(|(a, b)| plane.holds(a) || plane.holds(b));
        let (origins, vectors): (Vec<[f32; 2]>, Vec<[f32; 2]>) = inside
            .map(|(a, b)| {
                let (a, b) = (plane.at(a), plane.at(b));
                (a, [b[0] - a[0], b[1] - a[1]])
            })
            .unzip();
        let a = rerun::Arrows2D::from_vectors(vectors).with_origins(origins);
        let a = a.with_colors([style.color]).with_radii([style.radius]);
        let r = self.rec.log(path, &a.with_draw_order(style.order));
        self.keep(r);
    }

    fn strips(
        &mut self,
        path: &str,
        strips: &[Vec<Vector<D>>],
        colors: &[[u8; 3]],
        labels: Vec<String>,
        style: Style,
    ) {
        if D == 3 {
            let world: Vec<Vec<[f32; 3]>> = strips.iter().map(|s| self.world_all(s)).collect();
            let l = rerun::LineStrips3D::new(world)
                .with_colors(colors.to_vec())
                .with_labels(labels.clone());
            let r = self.rec.log(path, &l.with_radii([style.radius]));
            self.keep(r);
        }
        let Some((plane, path)) = self.plane_of(path) else {
            return;
        };
        let inside: Vec<usize> = (0..strips.len())
            .filter(|&i| strips[i].iter().any(|x| plane.holds(x)))
            .collect();
        let flat = inside
            .iter()
            .map(|&i| strips[i].iter().map(|x| plane.at(x)).collect::<Vec<_>>());
        let mut l = rerun::LineStrips2D::new(flat.collect::<Vec<_>>())
            .with_colors(inside.iter().map(|&i| colors[i]));
        if D == 2 {
            l = l.with_labels(labels);
        }
        let r = self.rec.log(
            path,
            &l.with_radii([style.radius]).with_draw_order(style.order),
        );
        self.keep(r);
    }

    fn moves(&mut self, from_to: &[(Vector<D>, Vector<D>)]) {
        let hop = |x: &Vector<D>| x.map(|c| c.floor() + 0.5);
        let drawn: Vec<(Vector<D>, Vector<D>)> = if self.hops {
            from_to.iter().map(|(a, b)| (hop(a), hop(b))).collect()
        } else {
            from_to.to_vec()
        };
        let radius = match (self.hops, D) {
            (true, _) => 0.08,
            (false, 2) => 0.04,
            _ => 0.05,
        };
        let style = Style {
            color: MOVE_COLOR,
            radius,
            order: 20.0,
        };
        self.arrows("world/corrector/moves", &drawn, style);
        let moved: Vec<Vector<D>> = from_to.iter().map(|(_, b)| *b).collect();
        let look = PointLook {
            radius: if D == 2 { 0.22 } else { 0.3 },
            order: 9.0,
            labels: None,
        };
        self.points("world/corrector/moved", &moved, vec![MOVE_COLOR], look);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_slice_keeps_y_up_and_cuts_one_layer() {
        let p = Plane::slice(&[4, 5, 6], 2, 3);
        assert_eq!((p.u, p.v, p.cols, p.rows), (0, 1, 4, 5));
        let x = Vector::<3>::new(1.5, 0.5, 3.2);
        assert!(p.holds(&x) && !p.holds(&Vector::<3>::new(1.5, 0.5, 2.9)));
        assert_eq!(p.at(&x), [1.5, 4.5]);
        assert_eq!(p.cell::<3>(1, 4), [1, 0, 3]);
        let across_y = Plane::slice(&[4, 5, 6], 1, 0);
        assert_eq!((across_y.u, across_y.v), (0, 2));
        let across_x = Plane::slice(&[4, 5, 6], 0, 0);
        assert_eq!((across_x.u, across_x.v), (2, 1));
    }

    #[test]
    fn the_2d_world_plane_puts_row_zero_at_the_top() {
        let p = Plane::world_2d(&[3, 2]);
        assert_eq!(p.cell::<2>(2, 0), [2, 1]);
        assert_eq!(p.at(&Vector::<2>::new(0.5, 0.5)), [0.5, 1.5]);
    }
}

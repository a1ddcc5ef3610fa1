//! The liquid's surface as a triangle mesh, for 3D recordings (issue 38 item 3).
//!
//! **Method.** SPH surface reconstruction with marching cubes by `splashsurf_lib` (the
//! SPlisHSPlasH group's library, MIT): every point gets an SPH density from its neighbours, the
//! colour field `sum_j (m / rho_j) W(x - x_j)` (about 1 inside the liquid, 0 outside) is sampled
//! on a sparse marching-cubes grid, and the mesh is its iso-surface at [`ISO_SURFACE`]. We do
//! not keep marching-cubes tables of our own.
//!
//! **Units.** Everything is in grid units (cell size 1), as the simulation works: positions and
//! the returned vertices run from 0 to `domain_cells` on each axis (x right, y up, z). Particles
//! sit `mu = k^3` to a cell, on a lattice of spacing `s = 1 / k` when at rest, and the constants
//! below are splashsurf's recommendations written relative to that spacing.
//!
//! **The deep.** The band methods (ccp's band, nbflip) keep no particles in the deep, the liquid
//! cells far under the surface. Each deep cell is filled with the `k^3` lattice points a seeded
//! cell would hold (its stratified samples without jitter), so the colour field there is about 1
//! as in any liquid cell and no inner surface is drawn around the deep.
//!
//! **Walls.** The liquid lies against the walls of the domain (a closed tank). Left alone, the
//! colour field falls to about half at a wall (no particles beyond it), the iso-surface would
//! draw back from the wall and round off every corner, and the water would look shrunk away from
//! the tank. Instead the points within the kernel's reach of a wall are mirrored across it
//! (across two or three walls near an edge or corner: ghost particles, the usual SPH wall
//! treatment), so the field at the wall is what it is inside and the iso-surface passes through
//! the wall into the ghosts. Every vertex is then clamped into the domain box: the part of the
//! surface outside the domain folds flat onto the wall, which closes the mesh with a cap exactly
//! where the water touches the wall. Clamping moves vertices but keeps the connectivity, so the
//! mesh stays closed and consistently oriented, and because the clamp is the nearest-point
//! projection onto a convex box (a point outside moves along a segment that stays outside),
//! the mesh winds once around exactly the points of the box that the unclamped surface enclosed:
//! its enclosed volume is that of the liquid inside the domain. The caps' normals are the walls'
//! outward normals, so a viewer shades them as flat water against glass.
//!
//! **Parameters.** Constants, not options: [`PARTICLE_RADIUS_PER_SPACING`],
//! [`SMOOTHING_LENGTH_PER_RADIUS`], [`CUBE_SIZE_PER_RADIUS`], [`ISO_SURFACE`]. With 8 particles
//! per cell (dam-3d) the kernel reaches one cell and the marching-cubes grid is half a cell.

use crate::step::Simulation;
use splashsurf_lib::nalgebra::Vector3;
use splashsurf_lib::{reconstruct_surface, Parameters};

/// The particle radius as a fraction of the particle spacing `s = 1 / mu^(1/3)` cells: one half,
/// SPlisHSPlasH's convention (particles of radius `r` seeded `2r` apart), which is what
/// splashsurf's parameters are written for. splashsurf gives each particle the volume `(2r)^3 =
/// s^3 = 1 / mu` cells, so the particles' volumes add up to the liquid's.
pub const PARTICLE_RADIUS_PER_SPACING: f64 = 0.5;

/// The SPH smoothing length in particle radii: 2, splashsurf's recommendation for
/// SPlisHSPlasH data (its CLI's `--smoothing-length 2.0`). The kernel's compact support is
/// twice the smoothing length, `4 r = 2 s`: one cell at 8 particles per cell.
pub const SMOOTHING_LENGTH_PER_RADIUS: f64 = 2.0;

/// The marching-cubes cube edge in particle radii: 2, one particle spacing (half a cell at 8
/// particles per cell), coarser than splashsurf's coarse example (1.1 r; 0.45 r fine) for cost:
/// at dam-3d 64^3 it took 0.33 s a frame against 1.2 s at 1 r (3.4x fewer triangles, 47k), and
/// the checks' volumes stay within 0.3% (NOTES-surface.md). Halving it quadruples the triangles.
pub const CUBE_SIZE_PER_RADIUS: f64 = 2.0;

/// The iso-value of the colour field (a fraction of the rest density) that separates liquid
/// from air: 0.6, splashsurf's default.
pub const ISO_SURFACE: f64 = 0.6;

/// A triangle mesh in grid units. Triangles are counter-clockwise seen from outside the liquid
/// (right-hand rule gives the outward normal); `normals` holds one unit outward normal per
/// vertex.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SurfaceMesh {
    pub vertices: Vec<[f32; 3]>,
    pub normals: Vec<[f32; 3]>,
    pub triangles: Vec<[u32; 3]>,
}

impl SurfaceMesh {
    /// The volume the mesh encloses, in cells, by the divergence theorem: the sum over
    /// triangles of the signed volumes of the tetrahedra they span with the origin. Positive
    /// for a closed mesh whose triangles face outward.
    pub fn enclosed_volume(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.vertices[i as usize].map(f64::from));
                let bxc = [
                    b[1] * c[2] - b[2] * c[1],
                    b[2] * c[0] - b[0] * c[2],
                    b[0] * c[1] - b[1] * c[0],
                ];
                (a[0] * bxc[0] + a[1] * bxc[1] + a[2] * bxc[2]) / 6.0
            })
            .sum()
    }
}

/// What the surface is made of, copied out of a simulation so that the reconstruction can run
/// on another thread while the simulation goes on ([`crate::frames`]).
#[derive(Clone, Debug)]
pub struct Liquid {
    /// The particles, in grid units.
    pub positions: Vec<[f64; 3]>,
    /// The liquid cells that hold no particles (the band methods' deep).
    pub deep_cells: Vec<[usize; 3]>,
    pub domain_cells: [usize; 3],
    /// Particles per cell.
    pub mu: usize,
}

impl Liquid {
    /// The liquid of a 3D simulation: its particles and, for the band methods, its deep cells.
    pub fn of<const D: usize>(sim: &Simulation<D>) -> Self {
        assert_eq!(D, 3, "surfaces are drawn for 3D runs only");
        let s = &sim.state;
        let g = &s.grid;
        let positions = (s.particles.pos.iter())
            .map(|p| std::array::from_fn(|k| p[k]))
            .collect();
        let deep_cells = (0..g.num_cells())
            .filter(|&cell| sim.method.is_deep(s, cell))
            .map(|cell| {
                let c = g.cell_coords(cell);
                std::array::from_fn(|k| c[k])
            })
            .collect();
        Self {
            positions,
            deep_cells,
            domain_cells: std::array::from_fn(|k| g.dims[k]),
            mu: s.config.mu() as usize,
        }
    }

    /// Its surface ([`reconstruct`]).
    pub fn surface(&self) -> SurfaceMesh {
        reconstruct(
            &self.positions,
            &self.deep_cells,
            self.domain_cells,
            self.mu,
        )
    }
}

/// The surface of the liquid made of `positions` (particles in grid units, inside the domain)
/// and `deep_cells` (liquid cells holding no particles, the band methods' deep), in a domain of
/// `domain_cells` cells with `mu` particles per cell (a cube, `k^3`). No points give an empty
/// mesh. See the module doc for the method, the deep and the walls.
pub fn reconstruct(
    positions: &[[f64; 3]],
    deep_cells: &[[usize; 3]],
    domain_cells: [usize; 3],
    mu: usize,
) -> SurfaceMesh {
    let per_axis = lattice_per_axis(mu);
    let mut points: Vec<[f64; 3]> = positions.to_vec();
    points.extend(deep_cells.iter().flat_map(|&c| lattice_points(c, per_axis)));
    if points.is_empty() {
        return SurfaceMesh::default();
    }
    let radius = PARTICLE_RADIUS_PER_SPACING / per_axis as f64;
    let support = 2.0 * SMOOTHING_LENGTH_PER_RADIUS * radius;
    let domain = domain_cells.map(|n| n as f64);
    let ghosts = wall_ghosts(&points, domain, support);
    points.extend(ghosts);
    let points: Vec<Vector3<f32>> = points
        .iter()
        .map(|p| Vector3::new(p[0] as f32, p[1] as f32, p[2] as f32))
        .collect();
    let mut params = Parameters::new(
        radius as f32,
        support as f32,
        (CUBE_SIZE_PER_RADIUS * radius) as f32,
    );
    params.iso_surface_threshold = ISO_SURFACE as f32;
    // The parameters are fixed and valid and the points finite, so splashsurf has nothing to
    // refuse; its errors are for user-given parameters and index overflow, which i64 rules out.
    let mesh = reconstruct_surface::<i64, f32>(&points, &params)
        .expect("splashsurf refused a reconstruction with fixed, valid parameters")
        .mesh;
    clamped_mesh(&mesh.vertices, &mesh.triangles, domain)
}

/// The particles per cell along an axis, `k` with `k^3 = mu` (seeding puts `mu = k^D` particles
/// per cell; for any other `mu`, the smallest `k` with `k^3 >= mu`, so that a deep cell is never
/// emptier than a liquid one).
fn lattice_per_axis(mu: usize) -> usize {
    (1..)
        .find(|k: &usize| k.pow(3) >= mu)
        .expect("k^3 grows past any mu")
}

/// The `k^3` points of cell `c` on the rest lattice, at `c + (i + 1/2) / k` on each axis.
fn lattice_points(c: [usize; 3], k: usize) -> impl Iterator<Item = [f64; 3]> {
    (0..k * k * k).map(move |s| {
        let sub = [s % k, (s / k) % k, s / (k * k)];
        std::array::from_fn(|a| c[a] as f64 + (sub[a] as f64 + 0.5) / k as f64)
    })
}

/// Mirror images of the points within `support` of a wall, across that wall, and across every
/// combination of the walls near a point (edges and corners), so that the colour field inside
/// the domain near a wall is as if the liquid went on beyond it.
fn wall_ghosts(points: &[[f64; 3]], domain: [f64; 3], support: f64) -> Vec<[f64; 3]> {
    let mut ghosts = Vec::new();
    for p in points {
        // Per axis, the coordinate itself and its mirror images across the near walls.
        let choices: [Vec<f64>; 3] = std::array::from_fn(|a| {
            let mut c = vec![p[a]];
            // A point on the wall is its own mirror image.
            if 0.0 < p[a] && p[a] < support {
                c.push(-p[a]);
            }
            if domain[a] - support < p[a] && p[a] < domain[a] {
                c.push(2.0 * domain[a] - p[a]);
            }
            c
        });
        for &x in &choices[0] {
            for &y in &choices[1] {
                for &z in &choices[2] {
                    if [x, y, z] != *p {
                        ghosts.push([x, y, z]);
                    }
                }
            }
        }
    }
    ghosts
}

/// The mesh with every vertex clamped into the domain box `[0, domain]` (the module doc says why
/// this closes the liquid at the walls), and its outward unit normals.
fn clamped_mesh(
    vertices: &[Vector3<f32>],
    triangles: &[[usize; 3]],
    domain: [f64; 3],
) -> SurfaceMesh {
    let vertices: Vec<[f32; 3]> = vertices
        .iter()
        .map(|v| std::array::from_fn(|a| v[a].clamp(0.0, domain[a] as f32)))
        .collect();
    // Per vertex, the sum of the outward normals of the walls it lies on.
    let walls: Vec<[f32; 3]> = vertices
        .iter()
        .map(|v| {
            std::array::from_fn(|a| {
                if v[a] <= 0.0 {
                    -1.0
                } else if v[a] >= domain[a] as f32 {
                    1.0
                } else {
                    0.0
                }
            })
        })
        .collect();
    let triangles: Vec<[u32; 3]> = triangles
        .iter()
        .map(|t| t.map(|i| u32::try_from(i).expect("a surface mesh of over 4e9 vertices")))
        .collect();
    let normals = vertex_normals(&vertices, &triangles, &walls);
    SurfaceMesh {
        vertices,
        normals,
        triangles,
    }
}

/// Unit outward normals per vertex: for a vertex on a wall, the wall's outward normal (the sum of
/// the walls' at an edge or corner), else the area-weighted mean of its triangles' normals. On
/// the wall the triangles folded flat by the clamp may face either way, so their mean is no
/// guide there; the wall's normal is, and it shades the cap as flat water against the wall
/// (the waterline, on both the wall and the free surface, takes the wall's too). A vertex all of whose triangles have zero area draws nothing; it gets
/// `+y`, so that every normal is a unit vector.
fn vertex_normals(
    vertices: &[[f32; 3]],
    triangles: &[[u32; 3]],
    walls: &[[f32; 3]],
) -> Vec<[f32; 3]> {
    let mut sums = vec![[0.0f64; 3]; vertices.len()];
    for t in triangles {
        let [a, b, c] = t.map(|i| vertices[i as usize].map(f64::from));
        let (u, v) = (sub(b, a), sub(c, a));
        // Twice the triangle's area times its unit normal: the area weighting.
        let n = [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ];
        for &i in t {
            sums[i as usize] = std::array::from_fn(|k| sums[i as usize][k] + n[k]);
        }
    }
    sums.iter()
        .zip(walls)
        .map(|(s, w)| {
            let n = if *w != [0.0; 3] { w.map(f64::from) } else { *s };
            let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            if len > 0.0 {
                n.map(|x| (x / len) as f32)
            } else {
                [0.0, 1.0, 0.0]
            }
        })
        .collect()
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|k| a[k] - b[k])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lattice_per_axis_is_the_cube_root_of_mu() {
        assert_eq!(lattice_per_axis(1), 1);
        assert_eq!(lattice_per_axis(8), 2);
        assert_eq!(lattice_per_axis(27), 3);
        assert_eq!(lattice_per_axis(9), 3);
    }

    #[test]
    fn a_deep_cell_holds_the_rest_lattice_of_a_seeded_cell() {
        let pts: Vec<_> = lattice_points([3, 0, 5], 2).collect();
        assert_eq!(pts.len(), 8);
        assert!(pts.contains(&[3.25, 0.25, 5.25]));
        assert!(pts.contains(&[3.75, 0.75, 5.75]));
    }

    #[test]
    fn ghosts_mirror_across_each_near_wall_and_their_combinations() {
        let domain = [4.0, 4.0, 4.0];
        // Near the x = 0 and y = 0 walls (an edge): three images.
        let g = wall_ghosts(&[[0.25, 0.5, 2.0]], domain, 1.0);
        assert_eq!(g.len(), 3);
        for want in [[-0.25, 0.5, 2.0], [0.25, -0.5, 2.0], [-0.25, -0.5, 2.0]] {
            assert!(g.contains(&want), "{want:?} missing from {g:?}");
        }
        // Near the top corner: seven images; far from every wall: none.
        assert_eq!(wall_ghosts(&[[3.5, 3.5, 3.5]], domain, 1.0).len(), 7);
        assert!(wall_ghosts(&[[2.0, 2.0, 2.0]], domain, 1.0).is_empty());
    }

    #[test]
    fn clamping_folds_outside_vertices_onto_the_wall_with_its_normal() {
        let v = [Vector3::new(-0.5f32, 1.0, 1.0), Vector3::new(1.0, 1.0, 1.0)];
        let m = clamped_mesh(&v, &[], [2.0, 2.0, 2.0]);
        assert_eq!(m.vertices[0], [0.0, 1.0, 1.0]);
        assert_eq!(m.normals[0], [-1.0, 0.0, 0.0]);
        assert_eq!(m.vertices[1], [1.0, 1.0, 1.0]);
    }

    #[test]
    fn a_unit_cube_encloses_volume_one() {
        let vertices = (0..8)
            .map(|i| [(i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32])
            .collect();
        // Two counter-clockwise (seen from outside) triangles per face.
        #[rustfmt::skip]
        let triangles = vec![
            [0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], // z = 0, z = 1
            [0, 1, 4], [1, 5, 4], [2, 6, 3], [3, 6, 7], // y = 0, y = 1
            [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5], // x = 0, x = 1
        ];
        let m = SurfaceMesh {
            vertices,
            normals: vec![],
            triangles,
        };
        assert!((m.enclosed_volume() - 1.0).abs() < 1e-12);
    }
}

//! `--export-frames DIR`: each drawn frame as files a renderer reads (issue 38 item 4).
//!
//! Every frame writes the particles as a PLY point cloud and, in 3D, the liquid's surface as a
//! PLY triangle mesh with vertex normals: binary little-endian PLY (Turk 1994; the form Blender,
//! ParaView, MeshLab and Houdini read), in metres, y up. Names say scene, run, frame and time:
//! `dam-3d_ccp_f0012_t0.4800s_surface.ply`, `..._particles.ply`; the frame number sorts them.
//!
//! Particles carry `x y z` (m) and `vx vy vz` (m/s) as `float`; 2D points lie at `z = 0`. Mesh
//! vertices carry `x y z` (m) and the outward unit normal `nx ny nz`; faces are
//! counter-clockwise seen from outside the liquid, as `uchar`-counted lists of `uint`.

use crate::cmd::cli::ExportArgs;
use crate::frames::{Frame, FrameNeeds, FrameSink};
use crate::scene::Scene;
use crate::surface::SurfaceMesh;
use anyhow::{Context, Result};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// A sink writing each frame into `dir` (created here, so that a bad folder fails before the
/// run), named after `scene` and `run` (the method, with its obstacle mode in a comparison);
/// positions scaled by `cell_size_m` to metres.
pub fn sink(dir: &Path, scene: &str, run: &str, cell_size_m: f64) -> Result<FrameSink> {
    std::fs::create_dir_all(dir).with_context(|| {
        format!(
            "--export-frames: cannot create directory '{}'",
            dir.display()
        )
    })?;
    let (dir, stem) = (dir.to_path_buf(), format!("{scene}_{run}"));
    Ok(Box::new(move |f: &Frame| {
        let name = |what: &str| -> PathBuf {
            dir.join(format!(
                "{stem}_f{:04}_t{:.4}s_{what}.ply",
                f.index, f.time_secs
            ))
        };
        let h = cell_size_m as f32;
        write_file(&name("particles"), |w| {
            write_points(w, &f.positions, &f.velocities, h)
        })?;
        if let Some(mesh) = &f.surface {
            write_file(&name("surface"), |w| write_mesh(w, mesh, h))?;
        }
        Ok(())
    }))
}

/// The sink `--export-frames` asks for, if it does: particles, and in 3D the surface.
pub fn requested(
    args: &ExportArgs,
    scene: &Scene,
    run: &str,
) -> Result<Option<(FrameSink, FrameNeeds)>> {
    let Some(dir) = &args.export_frames else {
        return Ok(None);
    };
    let needs = FrameNeeds {
        particles: true,
        surface: scene.dim() == 3,
    };
    Ok(Some((
        sink(dir, scene.name(), run, scene.cell_size_m)?,
        needs,
    )))
}

/// Writes `path` through `body`, naming the file in any error.
fn write_file(path: &Path, body: impl FnOnce(&mut dyn Write) -> std::io::Result<()>) -> Result<()> {
    let file = std::fs::File::create(path)
        .with_context(|| format!("--export-frames: cannot create '{}'", path.display()))?;
    let mut w = BufWriter::new(file);
    body(&mut w)
        .and_then(|()| w.flush())
        .with_context(|| format!("--export-frames: cannot write '{}'", path.display()))
}

/// A PLY point cloud: positions (cells) and velocities (cells/s), scaled by `h` (m per cell).
pub fn write_points(
    w: &mut dyn Write,
    positions: &[[f64; 3]],
    velocities: &[[f64; 3]],
    h: f32,
) -> std::io::Result<()> {
    write!(
        w,
        "ply\nformat binary_little_endian 1.0\ncomment cellflip particles, metres and m/s, y up\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         property float vx\nproperty float vy\nproperty float vz\nend_header\n",
        positions.len()
    )?;
    for (p, v) in positions.iter().zip(velocities) {
        for x in p.iter().chain(v) {
            w.write_all(&(*x as f32 * h).to_le_bytes())?;
        }
    }
    Ok(())
}

/// A PLY triangle mesh: vertices (cells) scaled by `h`, unit normals, faces.
pub fn write_mesh(w: &mut dyn Write, mesh: &SurfaceMesh, h: f32) -> std::io::Result<()> {
    write!(
        w,
        "ply\nformat binary_little_endian 1.0\ncomment cellflip liquid surface, metres, y up\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         property float nx\nproperty float ny\nproperty float nz\n\
         element face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        mesh.vertices.len(),
        mesh.triangles.len()
    )?;
    for (p, n) in mesh.vertices.iter().zip(&mesh.normals) {
        for x in p.iter().map(|x| x * h).chain(n.iter().copied()) {
            w.write_all(&x.to_le_bytes())?;
        }
    }
    for t in &mesh.triangles {
        w.write_all(&[3u8])?;
        for i in t {
            w.write_all(&i.to_le_bytes())?;
        }
    }
    Ok(())
}

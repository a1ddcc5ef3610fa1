//! `--export-frames` (issue 38 item 4) and the surface drawn from the frame worker: PLY files a
//! renderer reads, one per run, frame and kind, in metres; the recording's surface at every
//! frame the particles are drawn.

use crate::common::{self, cellflip_in, ok, scratch_dir};
use crate::surface::assert_closed_and_oriented;
use cellflip::surface::SurfaceMesh;
use std::collections::HashMap;
use std::path::Path;

/// A binary little-endian PLY file as read back: per element, its name, its count and its
/// rows (`float` properties as numbers; a face row is its vertex indices).
struct Ply {
    elements: Vec<(String, Vec<String>, Vec<Vec<f64>>)>,
}

impl Ply {
    /// Reads the header, then exactly the bytes it announces (a file longer or shorter fails).
    fn read(path: &Path) -> Ply {
        let bytes = std::fs::read(path).unwrap();
        let end = b"end_header\n";
        let at = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
        let header = std::str::from_utf8(&bytes[..at]).unwrap();
        let mut lines = header.lines();
        assert_eq!(lines.next(), Some("ply"));
        assert_eq!(lines.next(), Some("format binary_little_endian 1.0"));
        let mut elements: Vec<(String, usize, Vec<String>)> = vec![];
        for l in lines {
            let w: Vec<&str> = l.split_whitespace().collect();
            match w[..] {
                ["element", name, n] => elements.push((name.into(), n.parse().unwrap(), vec![])),
                ["property", "float", p] => elements.last_mut().unwrap().2.push(p.into()),
                ["property", "list", "uchar", "uint", p] => {
                    elements.last_mut().unwrap().2.push(format!("list {p}"))
                }
                ["comment", ..] | ["end_header"] => {}
                _ => panic!("{}: unexpected header line '{l}'", path.display()),
            }
        }
        let mut rest = &bytes[at..];
        let mut take = |n: usize| -> &[u8] {
            let (x, r) = rest.split_at(n);
            rest = r;
            x
        };
        let mut read = vec![];
        for (name, n, props) in elements {
            let list = props[0].starts_with("list");
            let rows = (0..n)
                .map(|_| match list {
                    false => (props.iter())
                        .map(|_| f32::from_le_bytes(take(4).try_into().unwrap()) as f64)
                        .collect(),
                    true => {
                        let count = take(1)[0];
                        (0..count)
                            .map(|_| u32::from_le_bytes(take(4).try_into().unwrap()) as f64)
                            .collect()
                    }
                })
                .collect();
            read.push((name, props, rows));
        }
        assert!(
            rest.is_empty(),
            "{}: {} bytes past the data",
            path.display(),
            rest.len()
        );
        Ply { elements: read }
    }

    fn rows(&self, element: &str) -> &[Vec<f64>] {
        &self.elements.iter().find(|e| e.0 == element).unwrap().2
    }
}

/// The exported files of a folder, by kind (`particles`, `surface`), sorted by name.
fn exported(dir: &Path) -> HashMap<String, Vec<String>> {
    let mut by_kind: HashMap<String, Vec<String>> = HashMap::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let name = e.unwrap().file_name().into_string().unwrap();
        let kind = name.rsplit('_').next().unwrap().trim_end_matches(".ply");
        by_kind.entry(kind.into()).or_default().push(name);
    }
    by_kind.values_mut().for_each(|v| v.sort());
    by_kind
}

#[test]
fn a_3d_run_exports_particles_and_a_closed_surface_per_frame_in_metres() {
    let dir = scratch_dir("export_3d");
    let frames = dir.join("frames");
    let args = [
        "run",
        "dam-3d",
        "--res",
        "16",
        "--duration",
        "0.1",
        "--no-record",
        "-q",
    ];
    let export = ["--export-frames", frames.to_str().unwrap()];
    ok(&cellflip_in(&dir, &[&args[..], &export[..]].concat()));
    let files = exported(&frames);
    // A frame at the start and one every 1/25 s: t = 0, 0.04, 0.08 (and the step past 0.1 is
    // not one).
    let particles = &files["particles"];
    assert_eq!(particles.len(), 3, "{files:?}");
    assert_eq!(files["surface"].len(), 3, "{files:?}");
    assert!(
        particles[0].starts_with("dam-3d_ccp_f0000_t0.0000s_"),
        "{particles:?}"
    );
    assert!(
        particles[1].starts_with("dam-3d_ccp_f0001_t0.04"),
        "{particles:?}"
    );
    // The first frame: the column as seeded, x in [0, 0.3] m, y in [0, 0.6] m, z in
    // [0.35, 0.65] m of the unit tank (cells snap the column to 1/16 m).
    let first = Ply::read(&frames.join(&particles[0]));
    let pts = first.rows("vertex");
    let mu = 8.0;
    let h: f64 = 1.0 / 16.0;
    for p in pts {
        assert!(
            p[0] <= 5.0 * h && p[1] <= 10.0 * h,
            "{p:?} outside the column"
        );
        assert!(
            (0.3125..=0.6875).contains(&p[2]),
            "{p:?} outside the column"
        );
        assert_eq!(&p[3..], &[0.0; 3], "at rest at the start");
    }
    let water = pts.len() as f64 / mu * h.powi(3);
    let surface = Ply::read(&frames.join(&files["surface"][0]));
    let mesh = SurfaceMesh {
        vertices: (surface.rows("vertex").iter())
            .map(|v| [v[0], v[1], v[2]].map(|x| x as f32))
            .collect(),
        normals: (surface.rows("vertex").iter())
            .map(|v| [v[3], v[4], v[5]].map(|x| x as f32))
            .collect(),
        triangles: (surface.rows("face").iter())
            .map(|f| {
                <[f64; 3]>::try_from(&f[..])
                    .expect("triangles")
                    .map(|i| i as u32)
            })
            .collect(),
    };
    assert_closed_and_oriented(&mesh);
    for (v, n) in mesh.vertices.iter().zip(&mesh.normals) {
        let len = n.iter().map(|x| x * x).sum::<f32>().sqrt();
        assert!((len - 1.0).abs() < 1e-5, "normal {n:?} at {v:?}");
        assert!(
            v.iter().all(|x| (0.0..=1.0).contains(x)),
            "{v:?} outside the tank"
        );
    }
    let v = mesh.enclosed_volume();
    println!("enclosed {v:.5} m^3, water {water:.5} m^3");
    // 10%: a column 5 cells wide, whose free faces (a third of its surface) the iso-surface may
    // place a fraction of a particle spacing off; against the walls the mesh is the wall.
    assert!((v - water).abs() <= 0.1 * water, "{v} against {water}");
}

#[test]
fn a_comparison_exports_each_runs_particles_and_a_2d_point_lies_at_z_0() {
    let dir = scratch_dir("export_compare");
    let frames = dir.join("frames");
    let args = [
        "compare",
        "dam-2d",
        "--methods",
        "flip,ccp",
        "--duration",
        "0.08",
    ];
    let export = [
        "--export-frames",
        frames.to_str().unwrap(),
        "--no-record",
        "-q",
    ];
    ok(&cellflip_in(&dir, &[&args[..], &export[..]].concat()));
    let files = exported(&frames);
    assert!(
        !files.contains_key("surface"),
        "2D has no surface: {files:?}"
    );
    let names = &files["particles"];
    for method in ["flip", "ccp"] {
        let own: Vec<&String> = (names.iter())
            .filter(|n| n.starts_with(&format!("dam-2d_{method}_f")))
            .collect();
        // The start and the frames at 0.04 and 0.08 s.
        assert_eq!(own.len(), 3, "{method}: {names:?}");
        let last = Ply::read(&frames.join(own[2]));
        let pts = last.rows("vertex");
        assert!(!pts.is_empty());
        assert!(
            pts.iter().all(|p| p[2] == 0.0 && p[5] == 0.0),
            "{method}: z not 0"
        );
        assert!(
            pts.iter().any(|p| p[4] < 0.0),
            "{method}: nothing falls by 0.08 s"
        );
    }
}

#[test]
fn an_export_folder_that_cannot_be_made_stops_the_run_before_it_starts_naming_it() {
    let dir = scratch_dir("export_refused");
    let blocker = dir.join("taken");
    std::fs::write(&blocker, "a file, not a folder").unwrap();
    let target = blocker.join("frames");
    let out = cellflip_in(
        &dir,
        &[
            "run",
            "dam-2d",
            "--steps",
            "3",
            "--no-record",
            "--export-frames",
            target.to_str().unwrap(),
        ],
    );
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("--export-frames") && stderr.contains(target.to_str().unwrap()),
        "{stderr}"
    );
}

#[test]
fn a_3d_recording_draws_the_surface_at_every_frame_it_draws_the_particles() {
    let dir = scratch_dir("surface_frames");
    let rec = dir.join("r.rrd");
    let args = ["run", "dam-3d", "--res", "16", "--duration", "0.1", "-q"];
    ok(&cellflip_in(
        &dir,
        &[&args[..], &["--save", rec.to_str().unwrap()]].concat(),
    ));
    let times = |entity: &str| -> Vec<i64> {
        common::on_timeline(&rec, entity, "sim_time", |c| vec![(); c.num_rows()])
            .into_iter()
            .map(|(t, ())| t)
            .collect()
    };
    let particles = times("world/particles");
    assert_eq!(particles.len(), 3, "{particles:?}");
    assert_eq!(times("world/surface"), particles);
    let plain = dir.join("plain.rrd");
    ok(&cellflip_in(
        &dir,
        &[
            &args[..],
            &["--no-surface", "--save", plain.to_str().unwrap()],
        ]
        .concat(),
    ));
    assert!(!common::logged_entities(&plain).contains("world/surface"));
}

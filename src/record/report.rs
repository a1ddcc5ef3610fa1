//! `cellflip report`'s recording: every run's volume and kinetic energy, a line per run in its
//! method's colour, one tab per scene.

use super::RecordError;
use crate::out::BoxError;
use rerun::blueprint::{Blueprint, Tabs, TimeSeriesView, Vertical};
use std::path::Path;

/// One run's time series for the report's comparison recording.
pub struct ComparisonSeries<'a> {
    pub scene: &'a str,
    pub method: &'a str,
    /// The method's line colour (RGB), as in the report's plots.
    pub color: [u8; 3],
    pub res: usize,
    pub seed: u64,
    /// `(simulated seconds, V/V* %)` and `(simulated seconds, kinetic energy per unit mass)`.
    pub volume: &'a [(f64, f64)],
    pub ke: &'a [(f64, f64)],
}

/// Entity-path (and file-name) part of a scene label: ASCII letters, digits, `-` and `_`,
/// anything else as `_`.
pub fn path_part(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Run `r`'s line colour among `runs`: its method's colour for the coarsest (then lowest-seed)
/// run of that method on its scene, mixed with white up to half way for the others, in order.
fn shade(runs: &[ComparisonSeries<'_>], r: &ComparisonSeries<'_>) -> [u8; 3] {
    let mut same: Vec<(usize, u64)> = (runs.iter())
        .filter(|o| o.scene == r.scene && o.method == r.method)
        .map(|o| (o.res, o.seed))
        .collect();
    same.sort_unstable();
    same.dedup();
    let rank = same.iter().position(|&x| x == (r.res, r.seed)).unwrap_or(0);
    let f = 0.5 * rank as f64 / same.len().saturating_sub(1).max(1) as f64;
    r.color
        .map(|c| (c as f64 + (255.0 - c as f64) * f).round() as u8)
}

/// `cellflip report`'s recording: every run's volume and kinetic energy on the `sim_time`
/// timeline, under `volume/<scene>/<method>/<cells>` and
/// `kinetic_energy/<scene>/<method>/<cells>` (`_s<seed>` appended when a scene runs with
/// several seeds), with one tab per scene comparing the methods.
pub fn write_comparison(path: &Path, runs: &[ComparisonSeries<'_>]) -> Result<(), RecordError> {
    let cannot = |e: BoxError| RecordError::File {
        path: path.into(),
        error: e,
    };
    let mut scenes: Vec<String> = vec![];
    for r in runs {
        let s = path_part(r.scene);
        if !scenes.contains(&s) {
            scenes.push(s);
        }
    }
    // One tab per scene: its volume above its kinetic energy, every run a line.
    let panel = |what: &str, s: &String| -> rerun::blueprint::ContainerLike {
        TimeSeriesView::new(format!("{s}: {what}"))
            .with_origin(format!("{what}/{s}"))
            .into()
    };
    let tabs = scenes.iter().map(|s| {
        Vertical::new([panel("volume", s), panel("kinetic_energy", s)])
            .with_name(s.clone())
            .into()
    });
    let blueprint = Blueprint::new(Tabs::new(tabs));
    let rec = rerun::RecordingStreamBuilder::new("cellflip")
        .recording_name("cellflip report")
        .send_properties(false)
        .with_blueprint(blueprint)
        .save(path)
        .map_err(|e| cannot(e.into()))?;
    rec.set_log_time_enabled(false);
    let several_seeds = |r: &ComparisonSeries<'_>| {
        runs.iter().any(|o| {
            o.scene == r.scene && o.method == r.method && o.res == r.res && o.seed != r.seed
        })
    };
    for r in runs {
        let mut leaf = format!("{}/{}/{}", path_part(r.scene), r.method, r.res);
        if several_seeds(r) {
            leaf += &format!("_s{}", r.seed);
        }
        for (what, series) in [("volume", r.volume), ("kinetic_energy", r.ke)] {
            let entity = format!("{what}/{leaf}");
            // The method's colour in both panels (the viewer would pick one per path), lighter
            // for each further resolution or seed of the same method and scene.
            let line = rerun::SeriesLines::new().with_colors([shade(runs, r)]);
            (rec.log_static(entity.as_str(), &line)).map_err(|e| cannot(e.into()))?;
            for &(t, v) in series {
                rec.set_duration_secs("sim_time", t);
                (rec.log(entity.as_str(), &rerun::Scalars::single(v)))
                    .map_err(|e| cannot(e.into()))?;
            }
        }
    }
    rec.flush_blocking().map_err(|e| cannot(e.into()))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A method keeps its colour on every scene; its finer resolutions are lighter, up to half
    /// way to white, and no two runs of one method on one scene share a colour.
    #[test]
    fn comparison_lines_take_their_methods_colour_lighter_per_resolution() {
        let run = |scene, method, res, color| ComparisonSeries {
            scene,
            method,
            color,
            res,
            seed: 1,
            volume: &[],
            ke: &[],
        };
        let (red, blue) = ([200, 20, 40], [30, 110, 180]);
        let runs = [
            run("dam", "ccp", 64, red),
            run("dam", "ccp", 32, red),
            run("dam", "ccp", 16, red),
            run("dam", "flip", 32, blue),
            run("drop", "ccp", 64, red),
        ];
        let c: Vec<[u8; 3]> = runs.iter().map(|r| shade(&runs, r)).collect();
        assert_eq!(c[2], red, "the coarsest run has the method's colour");
        assert_eq!(c[1], [214, 79, 94], "a quarter of the way to white");
        assert_eq!(c[0], [228, 138, 148], "the finest run half way to white");
        assert_eq!(
            (c[3], c[4]),
            (blue, red),
            "alone on its scene: the method's colour"
        );
    }
}

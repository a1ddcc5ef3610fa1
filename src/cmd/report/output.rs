//! `report.csv` (one row per run, every figure) and `report.md` (the paper's tables rebuilt,
//! speed against error, stability, and the Pareto conclusions a reader can check).

use super::measure::{figure_columns, share_column, Measured, COLUMNS};
use super::RunSpec;
use crate::methods::MethodKind;
use crate::metrics::Stage;
use std::fmt::Write;

/// Every column: the documented ones, then the methods' figures.
fn all_columns() -> Vec<String> {
    COLUMNS
        .iter()
        .map(|(c, _)| c.to_string())
        .chain(figure_columns())
        .collect()
}

/// Quotes a CSV field when it needs it.
fn field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn tables(spec: &RunSpec) -> &'static str {
    match (spec.accuracy, spec.stability) {
        (true, true) => "both",
        (false, true) => "stability",
        _ => "accuracy",
    }
}

/// `report.csv`.
pub fn csv(results: &[Measured]) -> String {
    let columns = all_columns();
    let mut out = columns.join(",") + "\n";
    for m in results {
        let row: Vec<String> = columns
            .iter()
            .map(|c| match c.as_str() {
                "scene" => field(&m.spec.label),
                "method" => m.spec.method.name().to_string(),
                "res" => m.res.to_string(),
                "seed" => m.seed.to_string(),
                "tables" => tables(&m.spec).into(),
                "status" => field(&m.status),
                "build" => field(&m.build),
                "machine" => field(&m.machine.as_ref().map_or(String::new(), |x| x.kind())),
                "copy_gb_s" => number(m.machine.as_ref().map_or(f64::NAN, |x| x.copy_gb_s)),
                "dim" => m.dim.to_string(),
                c => number(m.get(c)),
            })
            .collect();
        out += &(row.join(",") + "\n");
    }
    out
}

/// A figure for the CSV: empty when the run has none.
fn number(x: f64) -> String {
    if x.is_nan() {
        String::new()
    } else {
        format!("{x:?}")
    }
}

/// A figure for a table, with `digits` decimals; a dash when the run has none.
pub(super) fn cell(x: f64, digits: usize) -> String {
    if x.is_nan() {
        "-".into()
    } else {
        format!("{x:.digits$}")
    }
}

/// `report.md`.
pub fn markdown(
    specs: &[RunSpec],
    results: &[Measured],
    figures: &[String],
    title: &str,
    provenance: &str,
) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# {title}\n\n{provenance}\n");
    let _ = writeln!(
        s,
        "{} of {} runs, {}. Every column and formula: `docs/report.md` in cellflip's repository. Plots: {}.\n",
        results.len(),
        specs.len(),
        crate::stages::transfer::grid_to_particles_mode(),
        figures.iter().map(|f| format!("[{f}]({f})")).collect::<Vec<_>>().join(", ")
    );
    volume_table(&mut s, results);
    paper_time_table(&mut s, results);
    stage_table(&mut s, results);
    speed_error_table(&mut s, results);
    pareto(&mut s, results);
    stability_table(&mut s, results);
    let failed: Vec<&Measured> = results.iter().filter(|m| !m.ok()).collect();
    if !failed.is_empty() {
        let _ = writeln!(s, "## Runs that did not finish\n");
        for m in failed {
            let _ = writeln!(
                s,
                "- {} / {} / {}: {}",
                m.spec.label,
                m.spec.method.name(),
                m.res,
                m.status
            );
        }
    }
    s
}

/// The methods that took part, in registration order.
fn methods(results: &[Measured]) -> Vec<MethodKind> {
    MethodKind::ALL
        .iter()
        .copied()
        .filter(|k| results.iter().any(|m| m.spec.method == *k))
        .collect()
}

/// The distinct `(label, res)` of the runs picked, in matrix order.
fn scenes(results: &[Measured], pick: impl Fn(&Measured) -> bool) -> Vec<(String, usize)> {
    let mut out: Vec<(String, usize)> = vec![];
    for m in results.iter().filter(|m| pick(m)) {
        let key = (m.spec.label.clone(), m.res);
        if !out.contains(&key) {
            out.push(key);
        }
    }
    out
}

/// The run of a scene, resolution and method (the first seed).
fn find<'a>(
    results: &'a [Measured],
    scene: &(String, usize),
    k: MethodKind,
) -> Option<&'a Measured> {
    results
        .iter()
        .find(|m| m.spec.label == scene.0 && m.res == scene.1 && m.spec.method == k)
}

/// The paper's table of volume ranges: per scene, each method's lowest .. highest V/V*.
fn volume_table(s: &mut String, results: &[Measured]) {
    let ms = methods(results);
    let _ = writeln!(s, "## Volume range (% of V*, eq. volume)\n");
    let head: Vec<String> = ms.iter().map(|k| k.name().to_string()).collect();
    let _ = writeln!(
        s,
        "| scene | cells | {} |\n|---|---|{}",
        head.join(" | "),
        "---|".repeat(ms.len())
    );
    for sc in scenes(results, |m| m.spec.accuracy) {
        let cells: Vec<String> = ms
            .iter()
            .map(|&k| match find(results, &sc, k) {
                Some(m) if m.ok() => format!(
                    "{} .. {}",
                    cell(m.get("volume_min"), 2),
                    cell(m.get("volume_max"), 2)
                ),
                Some(m) => format!("({})", m.status),
                None => "-".into(),
            })
            .collect();
        let _ = writeln!(s, "| {} | {} | {} |", sc.0, sc.1, cells.join(" | "));
    }
    s.push('\n');
}

/// The paper's table of running times (tab. time) for the 3D runs: particles in the scene and
/// in the band, and the mean seconds per step of the Poisson solve, the correction, its LP
/// and its band step (MCFP in the paper, alg. find's paths here).
fn paper_time_table(s: &mut String, results: &[Measured]) {
    let rows: Vec<&Measured> = (results.iter())
        .filter(|m| m.ok() && m.spec.accuracy && m.dim == 3)
        .collect();
    if rows.is_empty() {
        return;
    }
    let _ = writeln!(
        s,
        "## Running time (the paper's tab. time)\n\nMeans over the steps; n counts a band method's imaginary particles too, band the particles it holds (a dash: it holds exactly the scene's).\n\n| scene | cells | method | n | band | Poisson s | correction s | of it LP s | band (MCFP) s |\n|---|---|---|---|---|---|---|---|---|"
    );
    for m in rows {
        let band = match has_band(m) {
            true => cell(m.get("held_mean"), 0),
            false => "-".into(),
        };
        let secs = |c: &str| cell(m.get(c) / 1e3, 3);
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {band} | {} | {} | {} | {} |",
            m.spec.label,
            m.res,
            m.spec.method.name(),
            cell(m.get("n_mean"), 0),
            secs("pressure_ms_mean"),
            secs("correct_ms_mean"),
            secs("ccp_solver_ms_mean"),
            secs("ccp_band_ms_mean"),
        );
    }
    s.push('\n');
}

/// Whether a run held other particles than the scene's (a band method: fewer, or more where
/// its resampling seeded more than it deleted).
fn has_band(m: &Measured) -> bool {
    m.get("held_mean") != m.get("n_mean")
}

/// The paper's table of per-stage times: median ms per step and each stage's share, per
/// method, on every scene run at its default resolution.
fn stage_table(s: &mut String, results: &[Measured]) {
    let _ = writeln!(s, "## Time per step and per stage\n");
    let names: Vec<&str> = Stage::ALL.iter().map(|st| st.name()).collect();
    let _ = writeln!(
        s,
        "| scene | cells | method | ms/step | {} |\n|---|---|---|---|{}",
        names
            .iter()
            .map(|n| format!("{n} %"))
            .collect::<Vec<_>>()
            .join(" | "),
        "---|".repeat(names.len())
    );
    for m in results.iter().filter(|m| m.ok() && m.spec.accuracy) {
        let shares: Vec<String> = Stage::ALL
            .iter()
            .map(|&st| cell(m.get(&share_column(st)), 1))
            .collect();
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} |",
            m.spec.label,
            m.res,
            m.spec.method.name(),
            cell(m.get("ms_per_step"), 2),
            shares.join(" | ")
        );
    }
    s.push('\n');
}

/// Speed against error: cost and every error of each accuracy run.
fn speed_error_table(s: &mut String, results: &[Measured]) {
    let _ = writeln!(s, "## Speed against error\n");
    let _ = writeln!(
        s,
        "| scene | cells | method | ms per simulated s | peak MiB | volume error % | front error % | column error % | compression | in solids | obstacle bottom / lowest (m), held |\n|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for m in results.iter().filter(|m| m.ok() && m.spec.accuracy) {
        let obstacle = if m.get("obstacle_bottom").is_nan() {
            "-".to_string()
        } else {
            format!(
                "{} / {}, {:.0}%",
                cell(m.get("obstacle_bottom"), 3),
                cell(m.get("obstacle_lowest"), 3),
                100.0 * m.get("obstacle_held")
            )
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            m.spec.label,
            m.res,
            m.spec.method.name(),
            cell(m.get("ms_per_sim_s"), 0),
            cell(m.get("peak_mib"), 0),
            cell(m.get("volume_error"), 2),
            cell(m.get("front_error"), 1),
            cell(m.get("column_error"), 1),
            cell(m.get("compression"), 2),
            cell(m.get("in_solids"), 0),
            obstacle
        );
    }
    s.push('\n');
}

/// Which runs are on the Pareto front of cost (ms per simulated second) against each error,
/// among the runs of one scene (all methods and resolutions).
fn pareto(s: &mut String, results: &[Measured]) {
    let _ = writeln!(
        s,
        "## Pareto front: cost against error\n\nA run is on the front when no other run of the same scene is both cheaper (ms per simulated second) and more accurate.\n"
    );
    let mut labels: Vec<&str> = vec![];
    for m in results.iter().filter(|m| m.ok() && m.spec.accuracy) {
        if !labels.contains(&m.spec.label.as_str()) {
            labels.push(&m.spec.label);
        }
    }
    for error in ["volume_error", "front_error"] {
        for label in &labels {
            let runs: Vec<&Measured> = results
                .iter()
                .filter(|m| m.ok() && m.spec.label == *label && !m.get(error).is_nan())
                .collect();
            if runs.len() < 2 {
                continue;
            }
            let front = pareto_front(&runs, error);
            let names: Vec<String> = front
                .iter()
                .map(|m| {
                    format!(
                        "{} at {} cells ({} ms/s, {:.2}%)",
                        m.spec.method.name(),
                        m.res,
                        cell(m.get("ms_per_sim_s"), 0),
                        m.get(error)
                    )
                })
                .collect();
            let _ = writeln!(s, "- {label}, {error}: {}", names.join("; "));
        }
    }
    s.push('\n');
}

/// The runs no other run beats on both cost and `error`, cheapest first.
pub fn pareto_front<'a>(runs: &[&'a Measured], error: &str) -> Vec<&'a Measured> {
    let mut front: Vec<&Measured> = runs
        .iter()
        .copied()
        .filter(|a| {
            !runs.iter().any(|b| {
                let (ca, cb) = (a.get("ms_per_sim_s"), b.get("ms_per_sim_s"));
                let (ea, eb) = (a.get(error), b.get(error));
                cb <= ca && eb <= ea && (cb < ca || eb < ea)
            })
        })
        .collect();
    front.sort_by(|a, b| a.get("ms_per_sim_s").total_cmp(&b.get("ms_per_sim_s")));
    front
}

/// Stability on the hard cases: finite, invariants kept, kinetic energy, or where it failed.
fn stability_table(s: &mut String, results: &[Measured]) {
    let rows: Vec<&Measured> = results.iter().filter(|m| m.spec.stability).collect();
    if rows.is_empty() {
        return;
    }
    let _ = writeln!(
        s,
        "## Stability on hard cases\n\nEvery step checks the invariants that apply to the method (finite state, particle count, nothing in static solids, and ccp's cell bounds); a run that breaks one stops there.\n"
    );
    let _ = writeln!(
        s,
        "| scene | cells | method | status | steps | volume range % | kinetic energy max / end (m^2/s^2) | compression |\n|---|---|---|---|---|---|---|---|"
    );
    for m in rows {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} .. {} | {} / {} | {} |",
            m.spec.label,
            m.res,
            m.spec.method.name(),
            m.status,
            cell(m.get("steps"), 0),
            cell(m.get("volume_min"), 2),
            cell(m.get("volume_max"), 2),
            cell(m.get("ke_max"), 4),
            cell(m.get("ke_end"), 4),
            cell(m.get("compression"), 2)
        );
    }
    s.push('\n');
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cmd::report::{RunSpec, Source};

    fn run(n: f64, held: f64) -> Measured {
        Measured {
            spec: RunSpec {
                label: "dam-3d".into(),
                source: Source::Named("dam-3d".into()),
                method: MethodKind::ALL[0],
                res: Some(100),
                seed: None,
                duration: None,
                accuracy: true,
                stability: false,
                budget: None,
            },
            res: 100,
            seed: 1,
            status: "ok".into(),
            dim: 3,
            build: crate::checkpoint::build().into(),
            machine: None,
            values: [("n_mean", n), ("held_mean", held)]
                .map(|(k, v)| (k.to_string(), v))
                .into(),
            volume: vec![],
            ke: vec![],
            front: vec![],
        }
    }

    /// A band shows whether the method holds fewer particles than the scene has (ccp's deep)
    /// or more (narrow-band FLIP seeding more than it deleted); a method holding exactly the
    /// scene's has none.
    #[test]
    fn the_band_column_shows_any_count_other_than_the_scenes() {
        assert!(has_band(&run(432_000.0, 389_646.0)));
        assert!(has_band(&run(432_000.0, 531_856.0)));
        assert!(!has_band(&run(432_000.0, 432_000.0)));
        let mut s = String::new();
        paper_time_table(&mut s, &[run(432_000.0, 531_856.0)]);
        assert!(s.contains("| 432000 | 531856 |"), "{s}");
    }
}

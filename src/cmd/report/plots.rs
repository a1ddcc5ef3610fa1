//! The report's plots, as PNG and SVG (plotters, with a bundled DejaVu Sans so that no system
//! font is needed): error against cost per method across resolutions (the Pareto view),
//! volume over time per method for each scene (the paper's fig. plot_volume), and the surge
//! front of Martin & Moyce against experiment per method.

use super::measure::Measured;
use crate::methods::MethodKind;
use crate::validation::{parse_csv, SURGE_FRONT_CSV};
use anyhow::{anyhow, Context, Result};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::Path;

/// The bundled font (DejaVu Sans, Bitstream Vera licence: assets/DejaVuSans-LICENSE.txt).
const FONT: &[u8] = include_bytes!("../../../assets/DejaVuSans.ttf");
const SIZE: (u32, u32) = (900, 560);

/// One line of a chart.
pub struct Series {
    pub name: String,
    pub color: RGBColor,
    pub points: Vec<(f64, f64)>,
    /// Markers only (experiment), or a line with markers at its points (few points).
    pub markers: bool,
}

/// A chart: title, axes and series.
pub struct Chart {
    pub title: String,
    pub x: String,
    pub y: String,
    /// The x values are `log10` of the quantity, labelled with the quantity itself.
    pub log_x: bool,
    /// The same for the y values.
    pub log_y: bool,
    pub series: Vec<Series>,
    /// Where the legend goes (away from the data).
    pub legend: SeriesLabelPosition,
    /// Words written on the plot, each under a point.
    pub notes: Vec<Note>,
}

/// A word written on a plot under the point `at` (in the chart's coordinates), its end, middle
/// or start there as `align` says.
pub struct Note {
    pub at: (f64, f64),
    pub text: String,
    pub align: HPos,
}

fn color(k: MethodKind) -> RGBColor {
    let [r, g, b] = k.rgb();
    RGBColor(r, g, b)
}

/// Writes every plot the results allow into `dir`; returns the file names.
pub fn all(dir: &Path, results: &[Measured], svg: bool) -> Result<Vec<String>> {
    let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
    let mut charts: Vec<(String, Chart)> = vec![];
    charts.extend(pareto(results));
    charts.extend(volumes(results));
    charts.extend(martin_moyce(results)?);
    charts.extend(time_per_step_3d(results));
    let mut names = vec![];
    for (stem, chart) in &charts {
        write(dir, stem, chart, svg)?;
        names.push(format!("{stem}.png"));
        if svg {
            names.push(format!("{stem}.svg"));
        }
    }
    Ok(names)
}

/// Writes `stem.png`, and `stem.svg` when asked.
pub fn write(dir: &Path, stem: &str, chart: &Chart, with_svg: bool) -> Result<()> {
    let svg = dir.join(format!("{stem}.svg"));
    if with_svg {
        let root = SVGBackend::new(&svg, SIZE).into_drawing_area();
        draw(&root, chart).map_err(|e| anyhow!("{e}"))?;
        root.present()
            .map_err(|e| anyhow!("cannot write '{}': {e}", svg.display()))?;
    }
    let mut pixels = vec![0u8; (SIZE.0 * SIZE.1 * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut pixels, SIZE).into_drawing_area();
        draw(&root, chart).map_err(|e| anyhow!("{e}"))?;
        root.present().map_err(|e| anyhow!("{e}"))?;
    }
    let png = dir.join(format!("{stem}.png"));
    let img = image::RgbImage::from_raw(SIZE.0, SIZE.1, pixels).expect("a full buffer");
    img.save(&png)
        .with_context(|| format!("cannot write '{}'", png.display()))
}

/// The x and y ranges of all series, padded a little.
fn ranges(c: &Chart) -> ((f64, f64), (f64, f64)) {
    let pts = c
        .series
        .iter()
        .flat_map(|s| s.points.iter())
        .filter(|p| p.0.is_finite() && p.1.is_finite());
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for &(x, y) in pts {
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
    }
    if !x0.is_finite() {
        return ((1.0, 2.0), (0.0, 1.0));
    }
    let pad = |a: f64, b: f64| match b > a {
        true => (a - 0.05 * (b - a), b + 0.05 * (b - a)),
        false => (a - 0.5, b + 0.5),
    };
    (pad(x0, x1), pad(y0, y1))
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    c: &Chart,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    root.fill(&WHITE)?;
    let ((x0, x1), (y0, y1)) = ranges(c);
    let mut b = ChartBuilder::on(root);
    b.caption(&c.title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60);
    let mut chart = b.build_cartesian_2d(x0..x1, y0..y1)?;
    plot_series(&mut chart, c)
}

/// The mesh with its axis labels, the series and their legend.
fn plot_series<'a, DB: DrawingBackend + 'a>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    c: &Chart,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    chart
        .configure_mesh()
        .x_desc(&c.x)
        .y_desc(&c.y)
        .x_labels(8)
        .x_label_formatter(&|x: &f64| if c.log_x { log_label(*x) } else { label(*x) })
        .y_label_formatter(&|y: &f64| if c.log_y { log_label(*y) } else { label(*y) })
        .light_line_style(RGBColor(238, 238, 238))
        .label_style(("sans-serif", 13))
        .draw()?;
    for s in &c.series {
        let color = s.color;
        let pts: Vec<(f64, f64)> = s
            .points
            .iter()
            .copied()
            .filter(|p| p.0.is_finite() && p.1.is_finite())
            .collect();
        let legend =
            move |(x, y): (i32, i32)| Rectangle::new([(x, y - 4), (x + 14, y + 4)], color.filled());
        if s.markers {
            chart
                .draw_series(pts.iter().map(|&p| Circle::new(p, 4, color.filled())))?
                .label(&s.name)
                .legend(legend);
        } else {
            chart
                .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))?
                .label(&s.name)
                .legend(legend);
            if pts.len() <= 12 {
                chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, color.filled())))?;
            }
        }
    }
    let note = |n: &Note| {
        let style = ("sans-serif", 12).into_font().color(&RGBColor(90, 90, 90));
        let style = style.pos(Pos::new(n.align, VPos::Top));
        EmptyElement::at(n.at) + Text::new(n.text.clone(), (0, 8), style)
    };
    chart.draw_series(c.notes.iter().map(note))?;
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(("sans-serif", 13))
        .position(c.legend.clone())
        .draw()
}

/// A tick label: at most three decimals, no trailing zeros; whole numbers from 100 on.
fn label(x: f64) -> String {
    if x.abs() >= 100.0 {
        return format!("{x:.0}");
    }
    let s = format!("{x:.3}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// A tick label on a log axis at `log10` value `x`: the quantity to two significant digits
/// (ticks fall between powers of ten), from 10,000 on in thousands, millions or billions
/// (`32k`, `3.2M`: the cells and particles of the time-per-step plots).
fn log_label(x: f64) -> String {
    let v = 10f64.powf(x);
    let unit = 10f64.powf(x.floor() - 1.0);
    let v = (v / unit).round() * unit;
    if v < 1e4 {
        return label(v);
    }
    let (scale, suffix) = [(1e9, "G"), (1e6, "M"), (1e3, "k")]
        .into_iter()
        .find(|&(s, _)| v >= s)
        .expect("v >= 1e4");
    format!("{}{suffix}", label(v / scale))
}

/// The labels of the accuracy runs, in matrix order.
fn labels(results: &[Measured]) -> Vec<String> {
    let mut out: Vec<String> = vec![];
    for m in results
        .iter()
        .filter(|m| m.spec.accuracy && !m.volume.is_empty())
    {
        if !out.contains(&m.spec.label) {
            out.push(m.spec.label.clone());
        }
    }
    out
}

/// File-name part of a label.
fn slug(label: &str) -> String {
    label
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' {
                c
            } else {
                '-'
            }
        })
        .collect()
}

/// Per scene with more than one resolution: each method's errors against its cost across the
/// resolutions (volume error, and the surge-front error where there is one).
fn pareto(results: &[Measured]) -> Vec<(String, Chart)> {
    let mut out = vec![];
    for label in labels(results) {
        let runs: Vec<&Measured> = results
            .iter()
            .filter(|m| m.ok() && m.spec.label == label)
            .collect();
        let mut resolutions: Vec<usize> = runs.iter().map(|m| m.res).collect();
        resolutions.sort();
        resolutions.dedup();
        if resolutions.len() < 2 {
            continue;
        }
        for (error, what) in [
            ("volume_error", "volume error |V/V* - 1| (%)"),
            ("front_error", "surge-front error (%)"),
        ] {
            let series: Vec<Series> = MethodKind::ALL
                .iter()
                .map(|&k| Series {
                    name: k.name().to_string(),
                    color: color(k),
                    points: runs
                        .iter()
                        .filter(|m| m.spec.method == k)
                        .map(|m| (m.get("ms_per_sim_s").log10(), m.get(error)))
                        .collect(),
                    markers: false,
                })
                .filter(|s| s.points.iter().any(|p| p.1.is_finite()))
                .collect();
            if series.is_empty() {
                continue;
            }
            let chart = Chart {
                title: format!("{label}: {what} against cost, resolutions {resolutions:?}"),
                x: "wall time per simulated second (ms, log)".into(),
                y: what.into(),
                log_x: true,
                log_y: false,
                series,
                legend: SeriesLabelPosition::UpperRight,
                notes: vec![],
            };
            out.push((
                format!(
                    "pareto-{}-{}",
                    slug(&label),
                    error.trim_end_matches("_error")
                ),
                chart,
            ));
        }
    }
    out
}

/// Per scene: volume over time, one line per method (the first resolution and seed).
fn volumes(results: &[Measured]) -> Vec<(String, Chart)> {
    labels(results)
        .into_iter()
        .map(|label| {
            let first = results
                .iter()
                .find(|m| m.spec.label == label)
                .map(|m| (m.res, m.seed));
            let series = MethodKind::ALL
                .iter()
                .filter_map(|&k| {
                    let m = results.iter().find(|m| {
                        m.spec.label == label
                            && m.spec.method == k
                            && Some((m.res, m.seed)) == first
                    })?;
                    Some(Series {
                        name: k.name().to_string(),
                        color: color(k),
                        points: m.volume.clone(),
                        markers: false,
                    })
                })
                .collect();
            let chart = Chart {
                title: format!("{label}: volume over time"),
                x: "simulated time (s)".into(),
                y: "V / V* (%)".into(),
                log_x: false,
                log_y: false,
                series,
                legend: SeriesLabelPosition::LowerLeft,
                notes: vec![],
            };
            (format!("volume-{}", slug(&label)), chart)
        })
        .collect()
}

/// Every 3D run's time per step against its grid's cells, log-log, a marker per run and a
/// colour per method: how a step's cost grows with the grid across the scenes and sizes run
/// (the paper's tab. time at its sizes and at half of them, issue 76). None with fewer than
/// two grid sizes.
fn time_per_step_3d(results: &[Measured]) -> Option<(String, Chart)> {
    let runs: Vec<&Measured> = (results.iter())
        .filter(|m| m.ok() && m.dim == 3 && m.get("grid_cells") > 0.0)
        .collect();
    let mut sizes: Vec<u64> = runs.iter().map(|m| m.get("grid_cells") as u64).collect();
    sizes.sort();
    sizes.dedup();
    if sizes.len() < 2 {
        return None;
    }
    let at = |m: &&Measured| (m.get("grid_cells").log10(), m.get("ms_per_step").log10());
    let series = (MethodKind::ALL.iter())
        .map(|&k| Series {
            name: k.name().to_string(),
            color: color(k),
            points: (runs.iter().filter(|m| m.spec.method == k))
                .map(at)
                .collect(),
            markers: true,
        })
        .filter(|s| !s.points.is_empty())
        .collect();
    let kinds: Vec<Option<String>> = (runs.iter())
        .map(|m| m.machine.as_ref().map(|x| x.kind()))
        .collect();
    let named: Vec<(String, (f64, f64))> = (runs.iter().zip(on_other_machines(&kinds)))
        .map(|(m, other)| match (other, &m.machine) {
            (false, _) => (m.spec.label.clone(), at(m)),
            (true, Some(x)) => (format!("{} (on {})", m.spec.label, x.cpu), at(m)),
            (true, None) => (format!("{} (machine not recorded)", m.spec.label), at(m)),
        })
        .collect();
    let chart = Chart {
        title: "3D: time per step against the grid's cells".into(),
        x: "grid cells (log)".into(),
        y: "wall time per step (ms, log)".into(),
        log_x: true,
        log_y: true,
        series,
        legend: SeriesLabelPosition::UpperLeft,
        notes: column_notes(&named),
    };
    Some(("time-per-step-3d".into(), chart))
}

/// For each run of `kinds` (its kind of machine, `None` when not recorded), whether another
/// kind than the one that ran most of them ran it: timings compare only within one kind, so a
/// plot of several says which points are another's.
fn on_other_machines(kinds: &[Option<String>]) -> Vec<bool> {
    let count = |k: &Option<String>| kinds.iter().filter(|j| *j == k).count();
    let most = kinds.iter().max_by_key(|k| count(k));
    kinds.iter().map(|k| Some(k) != most).collect()
}

/// One note a column of points (the points of one name at one x): the name, under the
/// column's lowest point, ending there in the right third of the x range and starting there
/// in the left third, so that it stays on the plot.
fn column_notes(points: &[(String, (f64, f64))]) -> Vec<Note> {
    let xs = points.iter().map(|p| p.1 .0);
    let (lo, hi) = (
        xs.clone().fold(f64::MAX, f64::min),
        xs.fold(f64::MIN, f64::max),
    );
    let mut notes: Vec<Note> = vec![];
    for (name, (x, y)) in points {
        match notes.iter_mut().find(|n| n.text == *name && n.at.0 == *x) {
            Some(n) => n.at.1 = n.at.1.min(*y),
            None => notes.push(Note {
                at: (*x, *y),
                text: name.clone(),
                align: match (x - lo) / (hi - lo).max(f64::MIN_POSITIVE) {
                    f if f < 1.0 / 3.0 => HPos::Left,
                    f if f > 2.0 / 3.0 => HPos::Right,
                    _ => HPos::Center,
                },
            }),
        }
    }
    notes
}

/// The surge front against Martin & Moyce (1952), per method at the middle resolution.
fn martin_moyce(results: &[Measured]) -> Result<Vec<(String, Chart)>> {
    let runs: Vec<&Measured> = results.iter().filter(|m| !m.front.is_empty()).collect();
    if runs.is_empty() {
        return Ok(vec![]);
    }
    let mut res: Vec<usize> = runs.iter().map(|m| m.res).collect();
    res.sort();
    res.dedup();
    let mid = res[res.len() / 2];
    let data = parse_csv(SURGE_FRONT_CSV)?;
    let mut series = vec![Series {
        name: "Martin & Moyce 1952".into(),
        color: BLACK,
        points: data,
        markers: true,
    }];
    for m in runs.iter().filter(|m| m.res == mid) {
        series.push(Series {
            name: m.spec.method.name().to_string(),
            color: color(m.spec.method),
            points: m.front.clone(),
            markers: false,
        });
    }
    let chart = Chart {
        title: format!("Martin & Moyce dam break, surge front ({mid} cells)"),
        x: "T = t sqrt(2g/a)".into(),
        y: "Z = front / a".into(),
        log_x: false,
        log_y: false,
        series,
        legend: SeriesLabelPosition::UpperLeft,
        notes: vec![],
    };
    Ok(vec![("martin-moyce-front".into(), chart)])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One note a column of points, under its lowest point, aligned so as to stay on the plot.
    #[test]
    fn each_column_of_points_gets_one_note_under_its_lowest_point() {
        let p = |name: &str, x: f64, y: f64| (name.to_string(), (x, y));
        let points = [
            p("dam-3d", 6.0, 2.0),
            p("large-obstacle-3d", 5.6, 1.5),
            p("dam-3d", 6.0, 1.2),
            p("drop-3d", 7.4, 3.6),
            p("drop-3d", 6.5, 2.7),
            p("dam-3d", 6.0, 3.1),
        ];
        let notes = column_notes(&points);
        let got: Vec<(&str, (f64, f64))> = notes.iter().map(|n| (&n.text[..], n.at)).collect();
        let want = [
            ("dam-3d", (6.0, 1.2)),
            ("large-obstacle-3d", (5.6, 1.5)),
            ("drop-3d", (7.4, 3.6)),
            ("drop-3d", (6.5, 2.7)),
        ];
        assert_eq!(got, want);
        let aligns: Vec<HPos> = notes.iter().map(|n| n.align).collect();
        assert!(matches!(
            aligns[..],
            [HPos::Left, HPos::Left, HPos::Right, HPos::Center]
        ));
    }

    /// Only the runs of a kind other than the most common one are named by their machine.
    #[test]
    fn the_runs_of_another_machine_are_named_by_it() {
        let kind = |k: &str| Some(k.to_string());
        let (intel, amd) = (kind("Intel (2 cores)"), kind("AMD (2 cores)"));
        let kinds = [intel.clone(), amd.clone(), intel.clone(), None, intel];
        assert_eq!(on_other_machines(&kinds), [false, true, false, true, false]);
        assert_eq!(on_other_machines(&[amd.clone(), amd]), [false, false]);
    }

    #[test]
    fn a_log_axis_labels_its_ticks_with_two_significant_digits() {
        let at = |v: f64| log_label(v.log10());
        assert_eq!(at(63.0957), "63");
        assert_eq!(at(39.8107), "40");
        assert_eq!(at(6309.57), "6300");
        assert_eq!(at(0.0398107), "0.04");
        assert_eq!(at(1.0e7), "10M");
        assert_eq!(at(3.2e5), "320k");
        assert_eq!(at(3.2e6), "3.2M");
        assert_eq!(at(12_000.0), "12k");
        assert_eq!(at(2.5e10), "25G");
    }
}

//! Validation against experiment and physics (issue: foundation, item 7).

use cellflip::scene::Overrides;
use cellflip::validation;

#[test]
fn hydrostatic_2d_stays_at_rest_for_500_steps() {
    let hs = validation::hydrostatic(500).unwrap();
    assert!(
        hs.speed_fraction < 0.01,
        "max speed {} sqrt(gH)",
        hs.speed_fraction
    );
    assert!(hs.volume_min >= 99.0 && hs.volume_max <= 101.0, "{hs:?}");
}

/// Shift of the simulated dimensionless time T, as Lethe's dam-break example does (0.175):
/// the experiment's t = 0 is uncertain. Without it the mean error is about 11% (see docs/validation.md).
const MM_SHIFT_T: f64 = 0.175;

#[test]
fn martin_moyce_surge_front_within_10_percent() {
    let mm = validation::martin_moyce(&Overrides::default(), MM_SHIFT_T).unwrap();
    let e = mm.front_mean_relative_error();
    for r in &mm.front {
        eprintln!(
            "T {:.2}: Z exp {:.2} sim {:.2}",
            r.time, r.measured, r.simulated
        );
    }
    assert!(
        e <= 0.10,
        "surge front mean relative error {:.1}%",
        100.0 * e
    );
    // The residual column height is reported; it must at least follow the experiment.
    let eh = mm.height_mean_relative_error();
    assert!(
        eh <= 0.15,
        "column height mean relative error {:.1}%",
        100.0 * eh
    );
}

#[test]
fn csv_tables_parse_completely() {
    assert_eq!(
        validation::parse_csv(validation::SURGE_FRONT_CSV)
            .unwrap()
            .len(),
        16
    );
    assert_eq!(
        validation::parse_csv(validation::COLUMN_HEIGHT_CSV)
            .unwrap()
            .len(),
        17
    );
}

//! The real indoor scenes in `../shared/data/scenes/` load with the documented point counts,
//! and the two flats without a ceiling read as open to the sky.
//! Skips with a message when the folder is absent (a clone of the project alone).
#![allow(clippy::unwrap_used, clippy::print_stderr)]

use std::path::PathBuf;

use fu_mpc_examples::cloud_io::load_pcd;
use fu_mpc_examples::setup::open_to_the_sky;

#[test]
fn shared_scenes_load() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/scenes");
    if !dir.is_dir() {
        eprintln!("skipped: {} is absent", dir.display());
        return;
    }
    for (name, points, extent, open) in [
        ("pillar.pcd", 144_640, [14.5, 27.4, 3.9], false),
        ("apartment.pcd", 167_531, [39.9, 20.0, 5.9], true),
        ("ri_flight.pcd", 110_836, [39.9, 20.0, 5.9], true),
    ] {
        let cloud = load_pcd(&dir.join(name)).unwrap();
        assert_eq!(cloud.len(), points, "{name}");
        assert_eq!(open_to_the_sky(&cloud), open, "{name}");
        for k in 0..3 {
            let lo = cloud.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min);
            let hi = cloud.iter().map(|p| p[k]).fold(f64::NEG_INFINITY, f64::max);
            assert!(
                (hi - lo - extent[k]).abs() < 0.15,
                "{name} axis {k}: {}",
                hi - lo
            );
        }
    }
}

//! Parses the 19 TSPLIB ATSP instances of `../shared/data/tsplib/` and checks their sizes
//! against `optima.tsv`. Skips with a message when the data folder is absent.

use std::path::Path;

use topo_tsp::{ProblemKind, parse_tsplib};

#[test]
fn all_atsp_instances_parse_with_their_dimension() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/tsplib");
    let Ok(optima) = std::fs::read_to_string(dir.join("optima.tsv")) else {
        eprintln!(
            "skipping: {} not found (the shared data folder is not beside the project)",
            dir.display()
        );
        return;
    };
    let mut checked = 0;
    for line in optima.lines().filter(|l| !l.trim().is_empty()) {
        let cols: Vec<&str> = line.split('\t').collect();
        let (name, n) = match (
            cols.first(),
            cols.get(1).and_then(|v| v.trim().parse::<usize>().ok()),
        ) {
            (Some(name), Some(n)) => (name.trim(), n),
            _ => continue, // header
        };
        let text =
            std::fs::read_to_string(dir.join(format!("{name}.atsp"))).expect("instance file");
        let inst = parse_tsplib(&text).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(inst.kind, ProblemKind::Asymmetric, "{name}");
        assert_eq!(inst.matrix.len(), n, "{name}");
        checked += 1;
    }
    assert_eq!(checked, 19, "optima.tsv should list 19 instances");
}

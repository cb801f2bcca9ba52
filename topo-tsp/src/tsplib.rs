//! TSPLIB text parsing (from a `&str`: the library does no I/O).
//!
//! Supported: `TYPE: ATSP` or `TSP`; `EDGE_WEIGHT_TYPE: EXPLICIT` with `EDGE_WEIGHT_FORMAT`
//! `FULL_MATRIX`, `UPPER_ROW`, `LOWER_ROW`, `UPPER_DIAG_ROW` or `LOWER_DIAG_ROW`; and
//! `EDGE_WEIGHT_TYPE: EUC_2D` with a `NODE_COORD_SECTION` (distances rounded to the nearest
//! integer, as TSPLIB defines them). The size is the `DIMENSION` header, not the number in the
//! name, and diagonal entries (0, 9999, 100000000, …) are ignored.

use crate::error::{Result, TspError};
use crate::matrix::CostMatrix;

/// Whether an instance is asymmetric or symmetric.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProblemKind {
    /// `TYPE: ATSP`.
    Asymmetric,
    /// `TYPE: TSP`.
    Symmetric,
}

/// A parsed TSPLIB instance.
#[derive(Debug, Clone, PartialEq)]
pub struct TsplibInstance {
    /// The `NAME` header (empty if absent).
    pub name: String,
    /// The `TYPE` header.
    pub kind: ProblemKind,
    /// The arc costs.
    pub matrix: CostMatrix,
}

fn err(line: usize, reason: impl Into<String>) -> TspError {
    TspError::Parse {
        line,
        reason: reason.into(),
    }
}

#[derive(Clone, Copy, PartialEq)]
enum Format {
    Full,
    UpperRow,
    LowerRow,
    UpperDiagRow,
    LowerDiagRow,
}

/// Parses a TSPLIB instance.
///
/// # Errors
/// [`TspError::Parse`] with the 1-based line of the problem for unsupported types or formats,
/// missing headers, malformed or missing numbers (the `DIMENSION` must match the numbers
/// present, which are counted before any matrix is allocated); the errors of
/// [`CostMatrix::from_rows`] for bad costs and for more than [`CostMatrix::MAX_LEN`] nodes.
///
/// # Example
/// ```
/// use topo_tsp::parse_tsplib;
/// let text = "NAME: tiny\nTYPE: ATSP\nDIMENSION: 3\nEDGE_WEIGHT_TYPE: EXPLICIT\n\
///             EDGE_WEIGHT_FORMAT: FULL_MATRIX\nEDGE_WEIGHT_SECTION\n\
///             9999 1 2\n3 9999 4\n5 6 9999\nEOF\n";
/// let inst = parse_tsplib(text).unwrap();
/// assert_eq!(inst.name, "tiny");
/// assert_eq!(inst.matrix.len(), 3);
/// assert_eq!(inst.matrix.cost(2, 1), 6.0);
/// assert_eq!(inst.matrix.cost(1, 1), 0.0); // the diagonal sentinel is ignored
/// ```
pub fn parse_tsplib(text: &str) -> Result<TsplibInstance> {
    let mut name = String::new();
    let mut kind = None;
    // The DIMENSION and its line.
    let mut dim: Option<(usize, usize)> = None;
    let mut weight_type = None;
    let mut format = None;
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim()));
    let mut section = None;
    for (no, line) in lines.by_ref() {
        if line.is_empty() {
            continue;
        }
        let upper = line.to_ascii_uppercase();
        if upper.starts_with("EDGE_WEIGHT_SECTION") || upper.starts_with("NODE_COORD_SECTION") {
            section = Some((no, upper));
            break;
        }
        if upper == "EOF" {
            break;
        }
        let (key, value) = match line.split_once(':') {
            Some((k, v)) => (k.trim().to_ascii_uppercase(), v.trim()),
            None => return Err(err(no, format!("expected KEY: VALUE, got {line:?}"))),
        };
        match key.as_str() {
            "NAME" => name = value.to_string(),
            "TYPE" => {
                kind = Some(match value.to_ascii_uppercase().as_str() {
                    "ATSP" => ProblemKind::Asymmetric,
                    "TSP" => ProblemKind::Symmetric,
                    other => return Err(err(no, format!("unsupported TYPE {other}"))),
                });
            }
            "DIMENSION" => {
                let n = value
                    .parse()
                    .map_err(|_| err(no, format!("bad DIMENSION {value:?}")))?;
                dim = Some((n, no));
            }
            "EDGE_WEIGHT_TYPE" => weight_type = Some((no, value.to_ascii_uppercase())),
            "EDGE_WEIGHT_FORMAT" => {
                format = Some(match value.to_ascii_uppercase().as_str() {
                    "FULL_MATRIX" => Format::Full,
                    "UPPER_ROW" => Format::UpperRow,
                    "LOWER_ROW" => Format::LowerRow,
                    "UPPER_DIAG_ROW" => Format::UpperDiagRow,
                    "LOWER_DIAG_ROW" => Format::LowerDiagRow,
                    other => {
                        return Err(err(no, format!("unsupported EDGE_WEIGHT_FORMAT {other}")));
                    }
                });
            }
            // COMMENT, CAPACITY, DISPLAY_DATA_TYPE, …: not needed.
            _ => {}
        }
    }
    let (section_line, section) =
        section.ok_or_else(|| err(text.lines().count().max(1), "no data section"))?;
    let kind = kind.ok_or_else(|| err(section_line, "missing TYPE"))?;
    let (n, dim_line) = dim.ok_or_else(|| err(section_line, "missing DIMENSION"))?;
    if n == 0 {
        return Err(err(section_line, "DIMENSION must be at least 1"));
    }
    // Numbers of the section, each with its line.
    let mut numbers = Vec::new();
    for (no, line) in lines {
        if line.eq_ignore_ascii_case("EOF") || line.to_ascii_uppercase().ends_with("_SECTION") {
            break;
        }
        for tok in line.split_whitespace() {
            let v: f64 = tok
                .parse()
                .map_err(|_| err(no, format!("not a number: {tok:?}")))?;
            numbers.push((no, v));
        }
    }
    let last_line = numbers.last().map_or(section_line, |&(l, _)| l);
    let weight_type = weight_type.map_or("EXPLICIT".to_string(), |(_, t)| t);
    // The header's size is checked against the numbers present (overflow-free) and against
    // the matrix limit before anything of size n² is allocated.
    let too_large = || err(dim_line, format!("DIMENSION {n} is too large"));
    let mut rows;
    if section.starts_with("NODE_COORD_SECTION") {
        if weight_type != "EUC_2D" {
            return Err(err(
                section_line,
                format!("coordinates with EDGE_WEIGHT_TYPE {weight_type} are not supported"),
            ));
        }
        let expected = n.checked_mul(3).ok_or_else(too_large)?;
        if numbers.len() != expected {
            return Err(err(
                last_line,
                format!(
                    "expected {expected} numbers (index x y) for {n} nodes, found {}",
                    numbers.len()
                ),
            ));
        }
        CostMatrix::check_len(n)?;
        rows = vec![vec![0.0; n]; n];
        let xy: Vec<(f64, f64)> = numbers.chunks(3).map(|c| (c[1].1, c[2].1)).collect();
        for i in 0..n {
            for j in 0..n {
                let (dx, dy) = (xy[i].0 - xy[j].0, xy[i].1 - xy[j].1);
                // TSPLIB's nint.
                rows[i][j] = (dx.hypot(dy) + 0.5).floor();
            }
        }
    } else {
        if weight_type != "EXPLICIT" {
            return Err(err(
                section_line,
                format!("EDGE_WEIGHT_SECTION with EDGE_WEIGHT_TYPE {weight_type}"),
            ));
        }
        let format = format.ok_or_else(|| err(section_line, "missing EDGE_WEIGHT_FORMAT"))?;
        let expected = match format {
            Format::Full => n.checked_mul(n),
            Format::UpperRow | Format::LowerRow => n.checked_mul(n - 1).map(|c| c / 2),
            Format::UpperDiagRow | Format::LowerDiagRow => n
                .checked_add(1)
                .and_then(|m| m.checked_mul(n))
                .map(|c| c / 2),
        }
        .ok_or_else(too_large)?;
        if numbers.len() != expected {
            return Err(err(
                last_line,
                format!(
                    "expected {expected} weights for DIMENSION {n}, found {}",
                    numbers.len()
                ),
            ));
        }
        CostMatrix::check_len(n)?;
        let cells: Vec<(usize, usize)> = match format {
            Format::Full => (0..n).flat_map(|i| (0..n).map(move |j| (i, j))).collect(),
            Format::UpperRow => (0..n)
                .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
                .collect(),
            Format::UpperDiagRow => (0..n).flat_map(|i| (i..n).map(move |j| (i, j))).collect(),
            Format::LowerRow => (0..n).flat_map(|i| (0..i).map(move |j| (i, j))).collect(),
            Format::LowerDiagRow => (0..n).flat_map(|i| (0..=i).map(move |j| (i, j))).collect(),
        };
        rows = vec![vec![0.0; n]; n];
        for (&(i, j), &(no, v)) in cells.iter().zip(&numbers) {
            if i != j && !(v.is_finite() && v >= 0.0) {
                return Err(err(
                    no,
                    format!("weight ({i}, {j}) = {v} is negative or not finite"),
                ));
            }
            rows[i][j] = v;
            if format != Format::Full {
                rows[j][i] = v;
            }
        }
    }
    Ok(TsplibInstance {
        name,
        kind,
        matrix: CostMatrix::from_rows(&rows)?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triangular_and_euclidean_formats() {
        let upper = "TYPE: TSP\nDIMENSION: 3\nEDGE_WEIGHT_TYPE: EXPLICIT\nEDGE_WEIGHT_FORMAT: UPPER_ROW\nEDGE_WEIGHT_SECTION\n1 2\n3\nEOF";
        let m = parse_tsplib(upper).unwrap().matrix;
        assert_eq!(
            (
                m.cost(0, 1),
                m.cost(1, 0),
                m.cost(0, 2),
                m.cost(1, 2),
                m.cost(2, 1)
            ),
            (1.0, 1.0, 2.0, 3.0, 3.0)
        );
        let lower = "TYPE: TSP\nDIMENSION: 3\nEDGE_WEIGHT_TYPE: EXPLICIT\nEDGE_WEIGHT_FORMAT: LOWER_DIAG_ROW\nEDGE_WEIGHT_SECTION\n0\n1 0\n2 3 0\n";
        let m2 = parse_tsplib(lower).unwrap().matrix;
        assert_eq!(m, m2);
        let euc = "NAME : e\nTYPE : TSP\nDIMENSION : 3\nEDGE_WEIGHT_TYPE : EUC_2D\nNODE_COORD_SECTION\n1 0 0\n2 3 4\n3 0 1.6\nEOF\n";
        let m3 = parse_tsplib(euc).unwrap().matrix;
        assert_eq!(m3.cost(0, 1), 5.0);
        assert_eq!(m3.cost(0, 2), 2.0); // nint(1.6)
    }

    #[test]
    fn errors_carry_line_numbers() {
        let bad_number = "TYPE: ATSP\nDIMENSION: 2\nEDGE_WEIGHT_TYPE: EXPLICIT\nEDGE_WEIGHT_FORMAT: FULL_MATRIX\nEDGE_WEIGHT_SECTION\n0 1\n2 x\n";
        assert!(matches!(
            parse_tsplib(bad_number),
            Err(TspError::Parse { line: 7, .. })
        ));
        let short = "TYPE: ATSP\nDIMENSION: 3\nEDGE_WEIGHT_TYPE: EXPLICIT\nEDGE_WEIGHT_FORMAT: FULL_MATRIX\nEDGE_WEIGHT_SECTION\n0 1 2\n";
        assert!(matches!(
            parse_tsplib(short),
            Err(TspError::Parse { line: 6, .. })
        ));
        assert!(matches!(
            parse_tsplib("TYPE: CVRP\n"),
            Err(TspError::Parse { line: 1, .. })
        ));
        assert!(matches!(
            parse_tsplib("garbage line\n"),
            Err(TspError::Parse { line: 1, .. })
        ));
        assert!(matches!(parse_tsplib(""), Err(TspError::Parse { .. })));
        let no_dim = "TYPE: ATSP\nEDGE_WEIGHT_SECTION\n1\n";
        assert!(matches!(
            parse_tsplib(no_dim),
            Err(TspError::Parse { line: 2, .. })
        ));
        let negative = "TYPE: ATSP\nDIMENSION: 2\nEDGE_WEIGHT_TYPE: EXPLICIT\nEDGE_WEIGHT_FORMAT: FULL_MATRIX\nEDGE_WEIGHT_SECTION\n0 -1\n2 0\n";
        assert!(matches!(
            parse_tsplib(negative),
            Err(TspError::Parse { line: 6, .. })
        ));
    }

    #[test]
    fn huge_dimensions_are_errors_before_allocation() {
        // 10¹² weights announced, two present: counted before the n² matrix is allocated.
        let million = "TYPE: ATSP\nDIMENSION: 1000000\nEDGE_WEIGHT_TYPE: EXPLICIT\nEDGE_WEIGHT_FORMAT: FULL_MATRIX\nEDGE_WEIGHT_SECTION\n0 1\n";
        assert!(matches!(
            parse_tsplib(million),
            Err(TspError::Parse { line: 6, .. })
        ));
        // Counts that overflow usize, in every format.
        let max = usize::MAX;
        for format in [
            "FULL_MATRIX",
            "UPPER_ROW",
            "LOWER_ROW",
            "UPPER_DIAG_ROW",
            "LOWER_DIAG_ROW",
        ] {
            let text = format!(
                "TYPE: ATSP\nDIMENSION: {max}\nEDGE_WEIGHT_TYPE: EXPLICIT\nEDGE_WEIGHT_FORMAT: {format}\nEDGE_WEIGHT_SECTION\n0 1\n"
            );
            assert!(
                matches!(parse_tsplib(&text), Err(TspError::Parse { line: 2, .. })),
                "{format}"
            );
        }
        let coords = format!(
            "TYPE: TSP\nDIMENSION: {max}\nEDGE_WEIGHT_TYPE: EUC_2D\nNODE_COORD_SECTION\n1 0 0\n"
        );
        assert!(matches!(
            parse_tsplib(&coords),
            Err(TspError::Parse { line: 2, .. })
        ));
        // All coordinates present, but more nodes than a matrix may have.
        let n = CostMatrix::MAX_LEN + 1;
        let mut big =
            format!("TYPE: TSP\nDIMENSION: {n}\nEDGE_WEIGHT_TYPE: EUC_2D\nNODE_COORD_SECTION\n");
        for i in 1..=n {
            big.push_str(&format!("{i} {i} 0\n"));
        }
        assert!(matches!(
            parse_tsplib(&big),
            Err(TspError::TooLarge {
                max: CostMatrix::MAX_LEN,
                ..
            })
        ));
    }
}

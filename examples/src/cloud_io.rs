//! Reading point-cloud scenes from PCD files (with `pcd-rs`) and PLY files (with `ply-rs-bw`).

use std::io::BufRead;
use std::path::Path;

use nalgebra::Point3;
use pcd_rs::{DynReader, Field};

/// Errors reading a point cloud.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CloudError {
    /// The file could not be opened.
    #[error("cannot open {path}: {source}")]
    Open {
        /// The path.
        path: String,
        /// The cause.
        source: std::io::Error,
    },
    /// A malformed header or record, as the PCD parser reports it.
    #[error("malformed PCD: {0}")]
    Malformed(String),
    /// No `x`, `y` or `z` field.
    #[error("the cloud has no {0} field")]
    MissingField(&'static str),
    /// Fewer points than the header announces.
    #[error("truncated PCD: the header announces {expected} points, the data holds {found}")]
    Truncated {
        /// Points announced.
        expected: u64,
        /// Points read.
        found: u64,
    },
}

/// The first value of a field as `f64`, if it is a scalar.
fn scalar(f: &Field) -> Option<f64> {
    // Every PCD value type converts to f64 (64-bit integers above 2^53 round).
    #[allow(clippy::cast_precision_loss)]
    let v = match f {
        Field::I8(v) => f64::from(*v.first()?),
        Field::I16(v) => f64::from(*v.first()?),
        Field::I32(v) => f64::from(*v.first()?),
        Field::I64(v) => *v.first()? as f64,
        Field::U8(v) => f64::from(*v.first()?),
        Field::U16(v) => f64::from(*v.first()?),
        Field::U32(v) => f64::from(*v.first()?),
        Field::U64(v) => *v.first()? as f64,
        Field::F32(v) => f64::from(*v.first()?),
        Field::F64(v) => *v.first()?,
    };
    Some(v)
}

/// Reads the x, y, z of every point of a PCD stream (v0.7; ascii, binary or
/// binary_compressed data; fields in any order). Points with a NaN coordinate (PCL writes
/// them for invalid returns) are dropped.
///
/// # Errors
/// [`CloudError::Malformed`] for a bad header or record, [`CloudError::MissingField`],
/// [`CloudError::Truncated`] when the data ends before the announced point count.
pub fn read_pcd(reader: impl BufRead) -> Result<Vec<Point3<f64>>, CloudError> {
    let reader =
        DynReader::from_reader(reader).map_err(|e| CloudError::Malformed(e.to_string()))?;
    let meta = reader.meta().clone();
    let index = |name: &'static str| {
        meta.field_defs
            .fields
            .iter()
            .position(|f| f.name == name)
            .ok_or(CloudError::MissingField(name))
    };
    let (ix, iy, iz) = (index("x")?, index("y")?, index("z")?);
    let mut out = Vec::new();
    let mut found = 0u64;
    for record in reader {
        let record = record.map_err(|e| CloudError::Malformed(e.to_string()))?;
        found += 1;
        let get = |i: usize| record.0.get(i).and_then(scalar);
        let (Some(x), Some(y), Some(z)) = (get(ix), get(iy), get(iz)) else {
            return Err(CloudError::Malformed(format!(
                "point {found} lacks a coordinate"
            )));
        };
        if x.is_finite() && y.is_finite() && z.is_finite() {
            out.push(Point3::new(x, y, z));
        }
    }
    if found < meta.num_points {
        return Err(CloudError::Truncated {
            expected: meta.num_points,
            found,
        });
    }
    Ok(out)
}

/// A scalar PLY property as `f64`.
fn ply_scalar(p: &ply_rs_bw::ply::Property) -> Option<f64> {
    use ply_rs_bw::ply::Property as P;
    Some(match p {
        P::Char(v) => f64::from(*v),
        P::UChar(v) => f64::from(*v),
        P::Short(v) => f64::from(*v),
        P::UShort(v) => f64::from(*v),
        P::Int(v) => f64::from(*v),
        P::UInt(v) => f64::from(*v),
        P::Float(v) => f64::from(*v),
        P::Double(v) => *v,
        _ => return None,
    })
}

/// Reads the `x`, `y`, `z` of every `vertex` of a PLY stream (ascii, binary little or big
/// endian). Vertices with a NaN coordinate are dropped.
///
/// # Errors
/// [`CloudError::Malformed`] for a bad header or payload (including a truncated one),
/// [`CloudError::MissingField`] without a `vertex` element or one of its coordinates.
pub fn read_ply(mut reader: impl std::io::Read) -> Result<Vec<Point3<f64>>, CloudError> {
    let parser = ply_rs_bw::parser::Parser::<ply_rs_bw::ply::DefaultElement>::new();
    let ply = parser
        .read_ply(&mut reader)
        .map_err(|e| CloudError::Malformed(e.to_string()))?;
    let vertices = ply
        .payload
        .get("vertex")
        .ok_or(CloudError::MissingField("vertex"))?;
    let mut out = Vec::with_capacity(vertices.len());
    for v in vertices {
        let get = |name: &'static str| {
            v.get(name)
                .and_then(ply_scalar)
                .ok_or(CloudError::MissingField(name))
        };
        let (x, y, z) = (get("x")?, get("y")?, get("z")?);
        if x.is_finite() && y.is_finite() && z.is_finite() {
            out.push(Point3::new(x, y, z));
        }
    }
    Ok(out)
}

/// Reads a PLY file (see [`read_ply`]).
///
/// # Errors
/// [`CloudError::Open`] if the file cannot be opened, otherwise as [`read_ply`].
pub fn load_ply(path: &Path) -> Result<Vec<Point3<f64>>, CloudError> {
    read_ply(open(path)?)
}

fn open(path: &Path) -> Result<std::io::BufReader<std::fs::File>, CloudError> {
    let file = std::fs::File::open(path).map_err(|source| CloudError::Open {
        path: path.display().to_string(),
        source,
    })?;
    Ok(std::io::BufReader::new(file))
}

/// Reads a PCD file (see [`read_pcd`]).
///
/// # Errors
/// [`CloudError::Open`] if the file cannot be opened, otherwise as [`read_pcd`].
pub fn load_pcd(path: &Path) -> Result<Vec<Point3<f64>>, CloudError> {
    read_pcd(open(path)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEADER: &str = "# .PCD v0.7\nVERSION 0.7\nFIELDS z x y\nSIZE 4 4 8\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 3\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3\nDATA ascii\n";

    #[test]
    fn ascii_with_fields_in_any_order() {
        let text = format!("{HEADER}3 1 2\n6 4 5\nnan 0 0\n");
        let pts = read_pcd(text.as_bytes()).unwrap();
        assert_eq!(
            pts,
            vec![Point3::new(1.0, 2.0, 3.0), Point3::new(4.0, 5.0, 6.0)]
        );
    }

    fn binary(points: &[[f32; 3]], announced: usize) -> Vec<u8> {
        let mut b = format!(
            "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {announced}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {announced}\nDATA binary\n"
        )
        .into_bytes();
        for p in points {
            for v in p {
                b.extend_from_slice(&v.to_le_bytes());
            }
        }
        b
    }

    #[test]
    fn binary_files() {
        let pts = [[1.0f32, 2.0, 3.0], [-4.5, 0.25, 8.0]];
        let got = read_pcd(&binary(&pts, 2)[..]).unwrap();
        assert_eq!(
            got,
            vec![Point3::new(1.0, 2.0, 3.0), Point3::new(-4.5, 0.25, 8.0)]
        );
        // Announcing more points than the data holds is an error.
        let e = read_pcd(&binary(&pts, 3)[..]).unwrap_err();
        assert!(
            matches!(e, CloudError::Truncated { .. } | CloudError::Malformed(_)),
            "{e}"
        );
        // Half a point is an error too.
        let mut cut = binary(&pts, 2);
        cut.truncate(cut.len() - 6);
        assert!(read_pcd(&cut[..]).is_err());
    }

    #[test]
    fn ply_ascii_and_binary() {
        let ascii = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty double z\nend_header\n1 2 3\n4 5 6\n";
        assert_eq!(
            read_ply(ascii.as_bytes()).unwrap(),
            vec![Point3::new(1.0, 2.0, 3.0), Point3::new(4.0, 5.0, 6.0)]
        );
        let mut bin = b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n".to_vec();
        for v in [1.5f32, -2.0, 3.25, 0.0, 1.0, 2.0] {
            bin.extend_from_slice(&v.to_le_bytes());
        }
        assert_eq!(read_ply(&bin[..]).unwrap()[0], Point3::new(1.5, -2.0, 3.25));
        // Truncated payload, bad header, no vertices.
        bin.truncate(bin.len() - 5);
        assert!(read_ply(&bin[..]).is_err());
        assert!(read_ply(&b"plx\nformat ascii 1.0\n"[..]).is_err());
        let faces = "ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n";
        assert!(matches!(
            read_ply(faces.as_bytes()),
            Err(CloudError::MissingField("vertex"))
        ));
        let short = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n";
        assert!(read_ply(short.as_bytes()).is_err());
    }

    #[test]
    fn truncated_and_malformed_files_are_errors() {
        let text = format!("{HEADER}3 1 2\n");
        assert!(matches!(
            read_pcd(text.as_bytes()),
            Err(CloudError::Truncated { .. }) | Err(CloudError::Malformed(_))
        ));
        let bad = "VERSION 0.7\nFIELDS x y\nnonsense\n";
        assert!(read_pcd(bad.as_bytes()).is_err());
        let no_z = "# .PCD v0.7\nVERSION 0.7\nFIELDS x y\nSIZE 4 4\nTYPE F F\nCOUNT 1 1\nWIDTH 1\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1\nDATA ascii\n1 2\n";
        assert!(matches!(
            read_pcd(no_z.as_bytes()),
            Err(CloudError::MissingField("z"))
        ));
        assert!(matches!(
            load_pcd(Path::new("/nonexistent/cloud.pcd")),
            Err(CloudError::Open { .. })
        ));
    }
}

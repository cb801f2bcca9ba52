//! Scenes by name for the programs: a generated scene (`maze`, `sinkhole`, `lavatube`,
//! `small`) or a PCD/PLY point cloud, with its world, flight area and explorable space.

use std::path::Path;

use nalgebra::Point3;

use crate::cloud_io::{CloudError, load_pcd, load_ply};
use crate::flight::Area;
use crate::scene::{Explorable, Scene};
use crate::world::{World, WorldError};

/// Voxel edge of point-cloud worlds \[m\].
pub const CLOUD_VOXEL: f64 = 0.1;

/// Width of the columns [`open_to_the_sky`] divides a cloud's footprint into \[m\].
pub const SKY_COLUMN: f64 = 0.5;

/// How far below a cloud's highest point a column's own highest point may lie and still
/// count as reaching the top \[m\] (see [`open_to_the_sky`]).
pub const SKY_BAND: f64 = 0.5;

/// Errors setting up a scene.
#[derive(Debug, thiserror::Error)]
pub enum SetupError {
    /// Neither a generated scene's name nor a `.pcd`/`.ply` file.
    #[error("unknown scene {0:?}: expected maze, sinkhole, lavatube, small, FILE.pcd or FILE.ply")]
    UnknownScene(String),
    /// The point cloud could not be read.
    #[error(transparent)]
    Cloud(#[from] CloudError),
    /// The world could not be built.
    #[error(transparent)]
    World(#[from] WorldError),
    /// The cloud has no finite point.
    #[error("the cloud has no finite point")]
    EmptyCloud,
}

/// A scene ready to fly.
#[derive(Debug)]
pub struct LoadedScene {
    /// Short name (the generator's, or the file's stem).
    pub name: String,
    /// The world the sensors see.
    pub world: World,
    /// Bounds and start.
    pub area: Area,
    /// The explorable free cells at the requested resolution.
    pub explorable: Explorable,
    /// Whether the scene is open to the sky (a point cloud without a ceiling, see
    /// [`open_to_the_sky`]; never for the generated scenes, which are closed). Beams that
    /// return nothing then say that nothing lies along them, and the programs let them clear
    /// the map unless told otherwise (see [`clears_no_return`]).
    pub open_top: bool,
}

/// Whether a point cloud has no ceiling: of the [`SKY_COLUMN`]-wide vertical columns its
/// finite points fall in, fewer than half hold a point within [`SKY_BAND`] of the cloud's
/// highest point.
///
/// A scanned room or building with its ceiling has points near its top over nearly all of
/// its footprint; a flat scanned without one (such as the shared `apartment.pcd`, 4 % of
/// its columns) has them only along its tallest walls. A roof that slopes by more than the
/// band, or a mast standing over a small part of the footprint, reads as open too; clearing
/// the map along beams without a return is still right there, since in the simulator a miss
/// means that nothing lies within the sensor's range. An empty cloud is closed.
///
/// # Example
/// ```
/// use fu_mpc_examples::setup::open_to_the_sky;
/// use nalgebra::Point3;
/// // A 4 m × 4 m floor at z = 0 and one wall 3 m high along x = 0.
/// let mut cloud = Vec::new();
/// for i in 0..40 {
///     for j in 0..40 {
///         cloud.push(Point3::new(0.1 * f64::from(i), 0.1 * f64::from(j), 0.0));
///     }
///     for k in 0..30 {
///         cloud.push(Point3::new(0.0, 0.1 * f64::from(i), 0.1 * f64::from(k)));
///     }
/// }
/// assert!(open_to_the_sky(&cloud));
/// // With a ceiling at z = 3 m it is closed.
/// for i in 0..40 {
///     for j in 0..40 {
///         cloud.push(Point3::new(0.1 * f64::from(i), 0.1 * f64::from(j), 3.0));
///     }
/// }
/// assert!(!open_to_the_sky(&cloud));
/// ```
pub fn open_to_the_sky(cloud: &[Point3<f64>]) -> bool {
    let finite = || cloud.iter().filter(|p| p.iter().all(|v| v.is_finite()));
    // The lowest x and y and the highest z.
    let Some((x0, y0, top)) = finite().fold(None, |acc, p| {
        let (x, y, z) = acc.unwrap_or((p.x, p.y, p.z));
        Some((x.min(p.x), y.min(p.y), z.max(p.z)))
    }) else {
        return false;
    };
    // Column -> its highest point.
    let mut columns: std::collections::BTreeMap<(i64, i64), f64> = Default::default();
    for p in finite() {
        // Finite offsets over a positive width; a cloud wider than 2^63 columns saturates.
        #[allow(clippy::cast_possible_truncation)]
        let key = (
            ((p.x - x0) / SKY_COLUMN).floor() as i64,
            ((p.y - y0) / SKY_COLUMN).floor() as i64,
        );
        let z = columns.entry(key).or_insert(f64::NEG_INFINITY);
        *z = z.max(p.z);
    }
    let high = columns.values().filter(|&&z| z >= top - SKY_BAND).count();
    2 * high < columns.len()
}

/// Whether beams that return nothing clear the map in a run on `scene`: `clear` forces it
/// on (and wins over `keep`), `keep` forces it off, and otherwise it follows
/// [`LoadedScene::open_top`].
///
/// # Example
/// ```
/// use fu_mpc_examples::setup::{clears_no_return, load_scene};
/// let small = load_scene("small", 1, 1.5, 0.2, None).unwrap();
/// assert!(!clears_no_return(false, false, &small));
/// assert!(clears_no_return(true, false, &small));
/// ```
pub fn clears_no_return(clear: bool, keep: bool, scene: &LoadedScene) -> bool {
    clear || (!keep && scene.open_top)
}

/// Loads scene `spec` with `seed` (generated scenes).
///
/// A point cloud becomes occupied [`CLOUD_VOXEL`] voxels; its area is
/// [`Area::of_cloud`] (the clearest point near `height` above the lowest point); its
/// explorable space is the cells of the bounding box at least a voxel from the cloud,
/// 6-connected to the start; it is [`LoadedScene::open_top`] when [`open_to_the_sky`].
/// `start`, if given, replaces the default start.
///
/// # Errors
/// [`SetupError`] for an unknown name, an unreadable cloud or an empty one.
pub fn load_scene(
    spec: &str,
    seed: u64,
    height: f64,
    resolution: f64,
    start: Option<Point3<f64>>,
) -> Result<LoadedScene, SetupError> {
    let generated = match spec {
        "maze" => Some(Scene::maze(seed)),
        "sinkhole" => Some(Scene::sinkhole(seed)),
        "lavatube" => Some(Scene::lava_tube(seed)),
        "small" => Some(Scene::small(seed)),
        _ => None,
    };
    if let Some(mut scene) = generated {
        if let Some(s) = start {
            scene.start = s;
        }
        return Ok(LoadedScene {
            name: scene.name.clone(),
            world: scene.world()?,
            area: Area::from(&scene),
            explorable: scene.explorable(resolution),
            open_top: false,
        });
    }
    let path = Path::new(spec);
    let cloud = match path.extension().and_then(|e| e.to_str()) {
        Some("pcd") => load_pcd(path)?,
        Some("ply") => load_ply(path)?,
        _ => return Err(SetupError::UnknownScene(spec.to_string())),
    };
    let world = World::from_points(&cloud, CLOUD_VOXEL)?;
    let mut area = Area::of_cloud(&cloud, &world, height).ok_or(SetupError::EmptyCloud)?;
    if let Some(s) = start {
        area.start = s;
    }
    let explorable = Explorable::from_fn(area.min, area.max, &area.start, resolution, |p| {
        world.closer_than(p, CLOUD_VOXEL)
    });
    let name = path
        .file_stem()
        .map_or_else(|| spec.to_string(), |s| s.to_string_lossy().into_owned());
    Ok(LoadedScene {
        name,
        world,
        area,
        explorable,
        open_top: open_to_the_sky(&cloud),
    })
}

/// Parses the programs' `--band MIN,MAX` (deg/s) into its two bounds; see
/// [`ExplorerConfig::with_band`](crate::explorer::ExplorerConfig::with_band), which checks
/// them.
///
/// # Errors
/// A message for anything but two comma-separated numbers.
///
/// # Example
/// ```
/// use fu_mpc_examples::setup::parse_band;
/// assert_eq!(parse_band("90, 180"), Ok([90.0, 180.0]));
/// assert!(parse_band("90").is_err());
/// ```
pub fn parse_band(s: &str) -> Result<[f64; 2], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>().map_err(|e| format!("{x:?}: {e}")))
        .collect::<Result<_, _>>()?;
    match v[..] {
        [lo, hi] => Ok([lo, hi]),
        _ => Err(format!("expected MIN,MAX in deg/s, got {s:?}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_files_and_starts() {
        assert!(matches!(
            load_scene("nowhere", 1, 1.5, 0.2, None),
            Err(SetupError::UnknownScene(_))
        ));
        assert!(matches!(
            load_scene("/no/such/file.pcd", 1, 1.5, 0.2, None),
            Err(SetupError::Cloud(_))
        ));
        let s = load_scene("small", 1, 1.5, 0.2, Some(Point3::new(2.0, 2.0, 1.0))).unwrap();
        assert_eq!(s.name, "small");
        assert_eq!(s.area.start, Point3::new(2.0, 2.0, 1.0));
        assert!(s.explorable.contains(&Point3::new(2.0, 2.0, 1.0)));
    }

    /// The points of an axis-aligned box's faces on a 0.1 m lattice, without its top face
    /// unless `ceiling`.
    fn room(size: [f64; 3], ceiling: bool) -> Vec<Point3<f64>> {
        let n = size.map(|s| (s / 0.1).round() as i32);
        let mut pts = Vec::new();
        for i in 0..=n[0] {
            for j in 0..=n[1] {
                for k in 0..=n[2] {
                    let face = [i == 0 || i == n[0], j == 0 || j == n[1], k == 0];
                    if face.iter().any(|&f| f) || (ceiling && k == n[2]) {
                        pts.push(Point3::new(
                            0.1 * f64::from(i),
                            0.1 * f64::from(j),
                            0.1 * f64::from(k),
                        ));
                    }
                }
            }
        }
        pts
    }

    #[test]
    fn clouds_without_a_ceiling_are_open_to_the_sky() {
        assert!(open_to_the_sky(&room([6.0, 4.0, 3.0], false)));
        assert!(!open_to_the_sky(&room([6.0, 4.0, 3.0], true)));
        // Non-finite points are ignored; a cloud with none finite, or none at all, is closed.
        let mut nan = room([6.0, 4.0, 3.0], true);
        nan.push(Point3::new(f64::NAN, 0.0, 100.0));
        nan.push(Point3::new(0.0, f64::INFINITY, 100.0));
        assert!(!open_to_the_sky(&nan));
        assert!(!open_to_the_sky(&[]));
        assert!(!open_to_the_sky(&[Point3::new(f64::NAN, 0.0, 0.0)]));
        // One point, or a flat patch: every column reaches the top.
        assert!(!open_to_the_sky(&[Point3::new(1.0, 2.0, 3.0)]));
        // A lone mast above a closed room makes it open (the room's ceiling lies far below
        // the top).
        let mut mast = room([6.0, 4.0, 3.0], true);
        mast.extend((0..50).map(|k| Point3::new(3.0, 2.0, 3.0 + 0.1 * f64::from(k))));
        assert!(open_to_the_sky(&mast));
    }

    #[test]
    fn the_no_return_option_follows_the_scene_unless_forced() {
        let mut s = load_scene("small", 1, 1.5, 0.2, None).unwrap();
        assert!(!s.open_top, "generated scenes are closed");
        assert!(!clears_no_return(false, false, &s));
        assert!(clears_no_return(true, false, &s));
        s.open_top = true;
        assert!(clears_no_return(false, false, &s));
        assert!(!clears_no_return(false, true, &s));
        assert!(clears_no_return(true, false, &s));
    }

    #[test]
    fn bands_are_two_numbers() {
        assert_eq!(parse_band("30,180"), Ok([30.0, 180.0]));
        assert_eq!(parse_band(" -90 , 90 "), Ok([-90.0, 90.0]));
        for bad in ["", "90", "90,180,270", "a,180", "90;180"] {
            assert!(parse_band(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn explorable_space_of_a_query_is_the_reachable_free_cells() {
        // A 4 × 2 × 1 m box split by a solid slab at x ∈ [1.9, 2.1]: only the start's half.
        let e = Explorable::from_fn(
            Point3::origin(),
            Point3::new(4.0, 2.0, 1.0),
            &Point3::new(0.5, 0.5, 0.5),
            0.2,
            |p| (p.x - 2.0).abs() < 0.1,
        );
        assert_eq!(e.count, 9 * 10 * 5);
        assert!(e.contains(&Point3::new(0.1, 1.9, 0.9)));
        assert!(!e.contains(&Point3::new(3.0, 1.0, 0.5)));
        assert!((e.coverage(|p| p.x < 1.0) - 5.0 / 9.0).abs() < 1e-12);
        // A start outside the region: nothing explorable, and full coverage by convention.
        let none = Explorable::from_fn(
            Point3::origin(),
            Point3::new(4.0, 2.0, 1.0),
            &Point3::new(-1.0, 0.5, 0.5),
            0.2,
            |_| false,
        );
        assert_eq!(none.count, 0);
        assert!((none.coverage(|_| false) - 1.0).abs() < 1e-12);
    }
}

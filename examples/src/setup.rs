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
}

/// Loads scene `spec` with `seed` (generated scenes).
///
/// A point cloud becomes occupied [`CLOUD_VOXEL`] voxels; its area is
/// [`Area::of_cloud`] (the clearest point near `height` above the lowest point); its
/// explorable space is the cells of the bounding box at least a voxel from the cloud,
/// 6-connected to the start. `start`, if given, replaces the default start.
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

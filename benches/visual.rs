//! Speed of the visual half: one 640x480 stereo pair, rendered; detected and triangulated by us
//! (left in full, right only in the epipolar band) against the C library detecting both images
//! at its defaults.

use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;
use std::path::Path;
use stereotag::geometry::Pose2;
use stereotag::render::{render_pair, RenderConfig, Renderer};
use stereotag::visual::stereo::{detect_pair, triangulate_tags, StereoConfig};
use stereotag::visual::tags::{CDetector, DetectorConfig, KorniaDetector, TagDetector};

fn visual(c: &mut Criterion) {
    let world =
        stereotag::io::load_world(Path::new("samples/office/world.yaml")).expect("office sample");
    let rig =
        stereotag::io::load_rig(Path::new("calibration/rigs/default.yaml")).expect("default rig");
    let pose = Pose2::new(1.0, 6.3, 2.35);
    let pair = render_pair(&world.world, &rig, pose, &RenderConfig::default()).expect("render");
    let rect = rig.rectify();

    let mut group = c.benchmark_group("stereo_pair_detect");
    let mut reference = CDetector::new(DetectorConfig::default()).expect("C detector");
    group.bench_function("apriltag_c_both_images (reference)", |b| {
        b.iter(|| {
            black_box(reference.detect(&pair.left).unwrap());
            black_box(reference.detect(&pair.right).unwrap());
        })
    });
    // Ours at the C library's contrast floor, at the survey's (`--min-contrast 30`), and with
    // the kornia backend.
    let c_at = |min_contrast| -> Box<dyn TagDetector> {
        Box::new(
            CDetector::new(DetectorConfig {
                min_contrast,
                ..DetectorConfig::default()
            })
            .expect("C detector"),
        )
    };
    let ours: [(&str, Box<dyn TagDetector>); 3] = [
        ("stereotag_band_and_triangulate", c_at(5)),
        ("stereotag_band_and_triangulate_min_contrast_30", c_at(30)),
        (
            "stereotag_band_and_triangulate_kornia",
            Box::new(KorniaDetector::new(DetectorConfig::default()).expect("kornia detector")),
        ),
    ];
    for (name, mut detector) in ours {
        group.bench_function(name, |b| {
            b.iter(|| {
                let (l, r) = detect_pair(detector.as_mut(), &pair.left, &pair.right).unwrap();
                black_box(triangulate_tags(
                    &rig,
                    &rect,
                    &l,
                    &r,
                    Some(0.16),
                    &StereoConfig::default(),
                ))
            })
        });
    }
    group.finish();

    test_photos(c);

    let mut group = c.benchmark_group("render");
    group.sample_size(10);
    // Ours: pixels no edge crosses traced with one ray; and every sample of every pixel.
    for (name, renderer) in [
        ("render_pair_640x480_4spp", Renderer::new(&rig)),
        (
            "render_pair_640x480_4spp_every_sample",
            Renderer::new(&rig).with_every_sample(),
        ),
    ] {
        group.bench_function(name, |b| {
            b.iter(|| {
                black_box(
                    renderer
                        .render(&world.world, pose, &RenderConfig::default())
                        .unwrap(),
                )
            })
        });
    }
    group.finish();

    building(c, &rig);
}

/// A building-size world: freiburg-079 (`../shared/data/radish`) imported as a lidar run, mapped
/// on its corrected poses, and its map traced into walls, as a user traces a world from their
/// robot's ROS map. `None` (and the group skipped) without the shared data.
fn building_world(dir: &Path) -> Option<stereotag::world::World> {
    let log = Path::new("../shared/data/radish/freiburg-079-corrected.log.gz");
    if !log.exists() {
        eprintln!("skipping the building group: {} not found", log.display());
        return None;
    }
    let run = dir.join("run");
    stereotag::workflow::import::import_carmen(&stereotag::workflow::import::CarmenRequest {
        carmen: log,
        out: &run,
        as_sonar: None,
        force: false,
    })
    .expect("import freiburg-079");
    let map = dir.join("map");
    stereotag::workflow::map::map(
        &stereotag::workflow::map::MapRequest {
            run_dir: &run,
            out: &map,
            poses: stereotag::dataset::PoseSource::GroundTruth,
            world: None,
            config: None,
            force: false,
            recording: stereotag::viz::RecordingRequest::none(),
        },
        &stereotag::progress::Silent,
    )
    .expect("map freiburg-079");
    let world = dir.join("world.yaml");
    std::fs::write(
        &world,
        "name: freiburg-079\nstart: {x_m: -5.0, y_m: 0.5, theta_rad: 0.0}\n\
         map: {yaml: map/map.yaml, wall_height_m: 2.5, simplify_m: 0.05, min_blob_cells: 4}\n",
    )
    .expect("write the world");
    Some(
        stereotag::io::load_world(&world)
            .expect("trace the map")
            .world,
    )
}

/// Rendering a pair in a building traced from a laser map (thousands of wall segments): the
/// wall grid against every wall tested (the reference), beside the office.
fn building(c: &mut Criterion, rig: &stereotag::camera::StereoRig) {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let Some(world) = building_world(dir.path()) else {
        return;
    };
    eprintln!("freiburg-079 traced: {} walls", world.walls.len());
    let office =
        stereotag::io::load_world(Path::new("samples/office/world.yaml")).expect("office sample");
    let mut group = c.benchmark_group("render_building");
    group.sample_size(10);
    let pose = Pose2::new(-5.0, 0.5, 0.0);
    for (name, renderer, world, pose) in [
        (
            "freiburg079_pair_640x480_every_wall_tested (reference)",
            Renderer::new(rig).with_every_wall_tested(),
            &world,
            pose,
        ),
        ("freiburg079_pair_640x480", Renderer::new(rig), &world, pose),
        (
            "office_pair_640x480",
            Renderer::new(rig),
            &office.world,
            Pose2::new(1.0, 6.3, 2.35),
        ),
    ] {
        group.bench_function(name, |b| {
            b.iter(|| {
                black_box(
                    renderer
                        .render(world, pose, &RenderConfig::default())
                        .unwrap(),
                )
            })
        });
    }
    group.finish();
}

/// The C library's own test photos at its regression settings (decimate 1, no edge
/// refinement): the C library, kornia-apriltag's own pipeline, and kornia's segmentation with
/// our quad stage, all three photos per iteration.
fn test_photos(c: &mut Criterion) {
    let dir = Path::new("../shared/data/apriltag_test");
    let Ok(entries) = std::fs::read_dir(dir) else {
        eprintln!("skipping the test-photo group: {} not found", dir.display());
        return;
    };
    let mut paths: Vec<_> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "jpg"))
        .collect();
    paths.sort();
    let photos: Vec<_> = paths
        .iter()
        .map(|p| stereotag::io::load_gray(p).expect("test photo"))
        .collect();
    let settings = DetectorConfig {
        decimate: 1.0,
        refine_edges: false,
        subpixel: false,
        ..DetectorConfig::default()
    };
    let mut group = c.benchmark_group("apriltag_test_photos");
    let detectors: [(&str, Box<dyn TagDetector>); 3] = [
        (
            "apriltag_c (reference)",
            Box::new(CDetector::new(settings.clone()).expect("C detector")),
        ),
        (
            "kornia_library",
            Box::new(KorniaDetector::library(settings.clone()).expect("kornia")),
        ),
        (
            "kornia_with_our_quad_stage",
            Box::new(KorniaDetector::new(settings).expect("kornia")),
        ),
    ];
    for (name, mut detector) in detectors {
        group.bench_function(name, |b| {
            b.iter(|| {
                for photo in &photos {
                    black_box(detector.detect(photo).unwrap());
                }
            })
        });
    }
    group.finish();
}

criterion_group!(benches, visual);
criterion_main!(benches);
